//! Protocol v1 as a contract, driven through the rig exactly as a serial client would.
mod common;
use common::Bench;
use morphlink::controller::Outputs;
use morphlink::protocol::{
    classify, format_error, is_final_reply as is_final, Assembled, LineAssembler, ERR_INVALID_LINE,
    ERR_LINE_TOO_LONG,
};
use proptest::prelude::*;

/// Feeds raw bytes through the bounded line assembler into the bench; returns reply lines.
fn feed(b: &mut Bench, bytes: &[u8]) -> Vec<String> {
    let mut asm = LineAssembler::new();
    let mut out = Vec::new();
    for &byte in bytes {
        match asm.push(byte) {
            Some(Assembled::Line(l)) => {
                let l = l.to_string();
                out.extend(b.send(&l));
            }
            Some(Assembled::TooLong) => out.push(format_error(&ERR_LINE_TOO_LONG).to_string()),
            Some(Assembled::Invalid) => out.push(format_error(&ERR_INVALID_LINE).to_string()),
            None => {}
        }
    }
    out
}

#[test]
fn every_command_gets_exactly_one_final_reply() {
    let mut b = Bench::new();
    for cmd in [
        "STATUS",
        "RANGE",
        "TABLE",
        "VERSION",
        "HELP",
        "STATS",
        "RESET",
        "ABORT",
        "SIM STATE",
        "bogus",
        "MORPH",
        "MORPH x",
    ] {
        let r = b.send(cmd);
        assert_eq!(r.iter().filter(|l| is_final(l)).count(), 1, "{cmd}: {r:?}");
        assert!(is_final(r.last().unwrap()), "{cmd}: {r:?}");
        assert!(
            r[..r.len() - 1].iter().all(|l| l.starts_with("data: ")),
            "{cmd}: {r:?}"
        );
    }
}

#[test]
fn commands_are_case_insensitive_and_crlf_is_accepted() {
    let mut b = Bench::new();
    let r = feed(&mut b, b"status\r\nRaNgE\r\n\r\n");
    assert_eq!(r.len(), 2, "{r:?}");
    assert!(r[0].starts_with("ok phase=idle target_mm=- "), "{r:?}");
    assert!(r[1].starts_with("ok min_mm="), "{r:?}");
}

#[test]
fn status_has_every_field_of_the_contract() {
    let mut b = Bench::new();
    let s = &b.send("STATUS")[0];
    for key in [
        "phase",
        "target_mm",
        "t_pla_c",
        "t_tca_c",
        "t_amb_c",
        "p_pla_w",
        "p_tca_w",
        "supply_v",
        "fault",
    ] {
        assert!(Bench::field(s, key).is_some(), "{key} missing in {s}");
    }
    let state = &b.send("SIM STATE")[0];
    for key in ["time_s", "radius_mm", "t_pla_c", "t_tca_c"] {
        assert!(
            Bench::field(state, key).is_some(),
            "{key} missing in {state}"
        );
    }
}

#[test]
fn table_lists_every_entry_and_range_matches_it() {
    let mut b = Bench::new();
    let t = b.send("TABLE");
    let rows: Vec<(f32, f32)> = t
        .iter()
        .filter_map(|l| l.strip_prefix("data: "))
        .map(|d| {
            let mut it = d.split(' ').map(|x| x.parse::<f32>().unwrap());
            (it.next().unwrap(), it.next().unwrap())
        })
        .collect();
    assert_eq!(rows.len(), morphlink::link::TABLE.len());
    let r = &b.send("RANGE")[0];
    let min: f32 = Bench::field(r, "min_mm").unwrap().parse().unwrap();
    let max: f32 = Bench::field(r, "max_mm").unwrap().parse().unwrap();
    // RANGE rounds its ends inward (each printed end is taken by MORPH), TABLE to the nearest.
    let (table_max, table_min) = (rows[0].1, rows[rows.len() - 1].1);
    assert!(
        max <= table_max && table_max - max <= 0.0101,
        "{max} vs {table_max}"
    );
    assert!(
        min >= table_min && min - table_min <= 0.0101,
        "{min} vs {table_min}"
    );
    for end in [min, max] {
        assert_eq!(b.send(&format!("MORPH {end}")), ["ok"], "{end}");
        assert_eq!(b.send("ABORT"), ["ok"]);
        b.run_for(1.0);
        b.send("RESET");
    }
}

#[test]
fn overlong_and_garbage_lines_get_errors_and_change_nothing() {
    let mut b = Bench::new();
    let mut bytes = vec![b'M'; 200];
    bytes.push(b'\n');
    bytes.extend_from_slice(&[0xff, 0xfe, b'\n']);
    bytes.extend_from_slice(b"MORPH 38 sideways\n");
    let r = feed(&mut b, &bytes);
    assert_eq!(r.len(), 3, "{r:?}");
    assert!(r[0].starts_with("error: line-too-long"), "{r:?}");
    assert!(r[1].starts_with("error: "), "{r:?}");
    assert!(r[2].starts_with("error: bad-argument"), "{r:?}");
    assert!(b.rig.ctrl.idle());
    assert_eq!(b.rig.ctrl.outputs(), Outputs::IDLE);
}

#[test]
fn sim_commands_check_their_arguments() {
    let mut b = Bench::new();
    assert!(b.send("SIM SUPPLY 99")[0].starts_with("error: out-of-range"));
    assert!(b.send("SIM AMBIENT 500")[0].starts_with("error: out-of-range"));
    assert!(b.send("SIM MEDIUM vacuum")[0].starts_with("error: bad-argument"));
    assert!(b.send("SIM FAULT melted pla")[0].starts_with("error: bad-argument"));
    assert!(b.send("SIM MEDIUM air")[0].starts_with("ok"));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// Arbitrary byte streams never panic, and every completed non-empty line gets exactly one
    /// final reply.
    #[test]
    fn any_input_gets_one_final_reply_per_line(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let mut b = Bench::new();
        let replies = feed(&mut b, &bytes);
        let mut asm = LineAssembler::new();
        let mut lines = 0;
        for &byte in &bytes {
            match asm.push(byte) {
                // Blank as the parser counts it: ASCII whitespace only (a vertical tab is a
                // word, answered as an unknown command).
                Some(Assembled::Line(l))
                    if l.trim_matches(|c: char| c.is_ascii_whitespace()).is_empty() => {}
                Some(_) => lines += 1,
                None => {}
            }
        }
        let finals = replies.iter().filter(|l| is_final(l)).count();
        prop_assert_eq!(finals, lines, "{:?}", replies);
        // Whatever was sent, heaters are off unless a MORPH was accepted.
        if !replies.iter().any(|l| l == "ok") {
            prop_assert_eq!(b.rig.ctrl.outputs(), Outputs::IDLE);
        }
    }

    /// Words from the command vocabulary in random order never panic and always get one reply.
    #[test]
    fn command_soup_gets_one_reply(words in proptest::collection::vec(
        prop::sample::select(vec!["MORPH", "SIM", "FAULT", "STATUS", "38", "-1", "1e9", "paper", "auto", "tca", "amb",
            "thermistor-open", "heater-stuck", "SUPPLY", "AMBIENT", "MEDIUM", "air", "RESET", "ABORT", "99999", ".", "nan"]),
        1..6)) {
        let mut b = Bench::new();
        let line = words.join(" ");
        let r = b.send(&line);
        prop_assert_eq!(r.iter().filter(|l| is_final(l)).count(), 1, "{}: {:?}", line, r);
    }
}

#[test]
fn every_reply_fits_the_shell_reply_buffer() {
    let mut b = Bench::new();
    for cmd in [
        "HELP",
        "TABLE",
        "STATUS",
        "RANGE",
        "VERSION",
        "STATS",
        "RESET",
        "ABORT",
        "MORPH 38",
        "MORPH 1",
        "bogus",
        "CONFIG",
        "CONFIG SET lock_timeout_s 300",
        "CONFIG RESET",
        "SAVE",
    ] {
        let bytes: usize = b
            .send(cmd)
            .iter()
            .filter(|l| !classify(l).is_unsolicited())
            .map(|l| l.len() + 1)
            .sum();
        assert!(
            bytes <= morphlink::controller::MAX_REPLY_BYTES,
            "{cmd}: {bytes} bytes"
        );
    }
    // CONFIG at its longest: every number at whichever end of its range prints longer (a set
    // the rises' share rule refuses keeps its value), on a link at rest.
    let mut b = Bench::new();
    let mut ends = Vec::new();
    morphlink::settings::Settings::DEFAULT.for_each(|spec, _| {
        if spec.choices.is_empty() {
            let text = |v: f32| format!("{v:.*}", spec.decimals as usize);
            let (lo, hi) = (text(spec.min), text(spec.max));
            ends.push((spec.name, if lo.len() > hi.len() { lo } else { hi }));
        }
    });
    for (name, v) in ends {
        b.send(&format!("CONFIG SET {name} {v}"));
    }
    let bytes: usize = b.send("CONFIG").iter().map(|l| l.len() + 1).sum();
    assert!(
        bytes <= morphlink::controller::MAX_REPLY_BYTES,
        "CONFIG at its longest: {bytes} bytes"
    );
}

#[test]
fn status_reports_the_target_temperatures_of_the_phase_and_the_mode_that_ran() {
    let mut b = Bench::new();
    let st = |b: &mut Bench| b.send("STATUS")[0].clone();
    let s = st(&mut b);
    assert!(
        s.contains(" pla_target_c=- tca_target_c=- mode=- "),
        "before any morph: {s}"
    );
    // auto runs the model-driven strategy: both heaters have a target in soften and bend.
    assert_eq!(b.send("MORPH 38"), ["ok"]);
    b.run_for(1.0);
    let s = st(&mut b);
    let num = |s: &str, k: &str| Bench::field(s, k).and_then(|v| v.parse::<f32>().ok());
    assert_eq!(num(&s, "pla_target_c"), Some(75.0), "{s}");
    let tca = num(&s, "tca_target_c").unwrap_or_else(|| panic!("no TCA target: {s}"));
    assert!(tca > 40.0 && tca < 110.0, "{s}");
    assert_eq!(
        Bench::field(&s, "mode").as_deref(),
        Some(morphlink::strategy::AUTO_STRATEGY.as_str())
    );
    // In lock the PLA cools (no target) while the TCA holds its target.
    assert!(b.run_until(300.0, |b| b.phase() == morphlink::vocab::Phase::Lock));
    let s = st(&mut b);
    assert_eq!(
        Bench::field(&s, "pla_target_c").as_deref(),
        Some("-"),
        "{s}"
    );
    assert_eq!(num(&s, "tca_target_c"), Some(tca), "{s}");
    // Done: no targets, the mode of the last morph stays.
    assert!(b.run_until(900.0, |b| b.phase() == morphlink::vocab::Phase::Idle));
    let s = st(&mut b);
    let auto = morphlink::strategy::AUTO_STRATEGY.as_str();
    assert!(
        s.contains(&format!(" pla_target_c=- tca_target_c=- mode={auto} ")),
        "after the morph: {s}"
    );
    // paper drives powers from the table: no temperature targets.
    assert_eq!(b.send("MORPH 40 paper"), ["ok"]);
    b.run_for(1.0);
    let s = st(&mut b);
    assert!(
        s.contains(" pla_target_c=- tca_target_c=- mode=paper "),
        "paper: {s}"
    );
    b.send("ABORT");
    let s = st(&mut b);
    assert!(
        s.contains(" pla_target_c=- tca_target_c=- mode=paper "),
        "{s}"
    );
}
