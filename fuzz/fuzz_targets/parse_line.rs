//! `command::parse_line` on arbitrary text: no panic, and an error reply fits a line.
#![no_main]

use libfuzzer_sys::fuzz_target;
use morphlink::protocol::{command, format_error};

fuzz_target!(|line: &str| {
    match command::parse_line(line) {
        Ok(_) => {}
        Err(e) => {
            let reply = format_error(&e);
            assert!(reply.starts_with("error: "), "{reply}");
        }
    }
});
