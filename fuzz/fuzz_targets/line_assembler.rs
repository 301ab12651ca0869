//! `LineAssembler::push` over arbitrary bytes: no panic; every finished line fits
//! `MAX_LINE`, holds no line ending, and parses without a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;
use morphlink::protocol::{parse_line, Assembled, LineAssembler, MAX_LINE};

fuzz_target!(|bytes: &[u8]| {
    let mut asm = LineAssembler::new();
    // Bytes of the current line since the last `\n`, line endings aside.
    let mut since_newline = 0usize;
    for &b in bytes {
        let got = asm.push(b);
        if b != b'\n' {
            assert!(got.is_none(), "only `\\n` ends a line");
            if b != b'\r' {
                since_newline += 1;
            }
            continue;
        }
        match got.expect("`\\n` always ends a line") {
            Assembled::Line(line) => {
                assert!(line.len() <= MAX_LINE && line.len() == since_newline);
                assert!(!line.contains(['\r', '\n']));
                let _ = parse_line(line);
            }
            Assembled::TooLong => assert!(since_newline > MAX_LINE),
            Assembled::Invalid => assert!(since_newline <= MAX_LINE),
        }
        since_newline = 0;
    }
});
