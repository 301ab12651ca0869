//! `LineAssembler::push` over arbitrary bytes: no panic; CR, LF and CRLF each end exactly one
//! line (the LF of a CRLF ends none); every finished line fits `MAX_LINE`, holds no line ending,
//! and parses without a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;
use morphlink::protocol::{parse_line, Assembled, LineAssembler, MAX_LINE};

fuzz_target!(|bytes: &[u8]| {
    let mut asm = LineAssembler::new();
    // Bytes of the current line since the last line ending.
    let mut since_end = 0usize;
    let mut after_cr = false;
    for &b in bytes {
        let got = asm.push(b);
        let ends = match b {
            b'\r' => true,
            b'\n' => !after_cr,
            _ => false,
        };
        after_cr = b == b'\r';
        if !ends {
            assert!(got.is_none(), "only CR, LF or the CR of a CRLF ends a line");
            if b != b'\n' {
                since_end += 1;
            }
            continue;
        }
        match got.expect("a line ending ends a line") {
            Assembled::Line(line) => {
                assert!(line.len() <= MAX_LINE && line.len() == since_end);
                assert!(!line.contains(['\r', '\n']));
                let _ = parse_line(line);
            }
            Assembled::TooLong => assert!(since_end > MAX_LINE),
            Assembled::Invalid => assert!(since_end <= MAX_LINE),
        }
        since_end = 0;
    }
});
