//! The settings on the whole system: `CONFIG`, `CONFIG SET`, `CONFIG RESET` and `SAVE` against
//! the controller on the simulated board, the live values changing what a morph does (on both
//! plants), and the boot with every kind of bad stored settings (docs/settings.md).

mod common;

use common::{Bench, Link, LINKS};
use morphlink::controller::Outputs;
use morphlink::settings::codec::{self, LoadError};
use morphlink::settings::store::{block_on_ready, SettingsStore};
use morphlink::settings::Settings;
use morphlink::vocab::Phase;
use morphlink_sim::rig::{SimFlash, SIM_FLASH_BYTES};

/// A lumped bench with an erased settings flash.
fn with_flash(flash: Option<SimFlash>) -> Bench {
    let mut b = Bench::new();
    b.rig.boot_storage(flash);
    b.tick();
    b
}

/// The `CONFIG` listing's data lines.
fn listing(b: &mut Bench) -> Vec<String> {
    let r = b.send("CONFIG");
    assert_eq!(
        r.last().map(String::as_str),
        Some("ok settings=25"),
        "{r:?}"
    );
    r[..r.len() - 1].to_vec()
}

/// A flash holding `bytes` as the stored blob (written through the real store).
fn flash_holding(bytes: &[u8]) -> SimFlash {
    let mut store = SettingsStore::new(SimFlash::new(), 0..SIM_FLASH_BYTES as u32).unwrap();
    block_on_ready(store.save_bytes(bytes)).unwrap();
    store.flash().clone()
}

#[test]
fn config_lists_every_setting_with_unit_value_and_range() {
    let mut b = Bench::new();
    let rows = listing(&mut b);
    assert_eq!(rows.len(), 25);
    for r in &rows {
        assert!(r.starts_with("data: "), "{r}");
        assert!(r.contains("default="), "{r}");
        assert!(r.contains(" range=") || r.contains(" choices="), "{r}");
    }
    assert!(
        rows.contains(&"data: lock_timeout_s=600.0 s range=30.0..900.0 default=600.0".to_string())
    );
}

#[test]
fn each_bad_config_set_is_refused_with_a_clear_error_and_changes_nothing() {
    let mut b = Bench::new();
    let before = listing(&mut b);
    let cases = [
        (
            "CONFIG SET",
            "error: bad-argument CONFIG SET needs a setting name and a value",
        ),
        (
            "CONFIG SET lock_timeout_s",
            "error: bad-argument CONFIG SET needs",
        ),
        (
            "CONFIG SET lock_timeout_s 300 400",
            "error: bad-argument CONFIG SET takes one name",
        ),
        (
            "CONFIG RESET now",
            "error: bad-argument CONFIG RESET takes no arguments",
        ),
        (
            "CONFIG LIST",
            "error: bad-argument CONFIG takes nothing, SET",
        ),
        ("SAVE now", "error: bad-argument SAVE takes no arguments"),
        (
            "CONFIG SET no_such 1",
            "error: bad-argument no setting named no_such",
        ),
        (
            "CONFIG SET lock_timeout_s abc",
            "error: bad-argument lock_timeout_s takes a number in 30.0..900.0 s",
        ),
        (
            "CONFIG SET lock_timeout_s 1e3",
            "error: bad-argument lock_timeout_s takes",
        ),
        (
            "CONFIG SET lock_timeout_s nan",
            "error: bad-argument lock_timeout_s takes",
        ),
        (
            "CONFIG SET lock_timeout_s 901",
            "error: out-of-range lock_timeout_s=901.0 s is outside 30.0..900.0 s",
        ),
        (
            "CONFIG SET lock_timeout_s -5",
            "error: out-of-range lock_timeout_s=-5.0",
        ),
        (
            "CONFIG SET pla_soft_target_c 125",
            "error: out-of-range pla_soft_target_c=125.0 C is outside 75.0..83.6 C",
        ),
        (
            "CONFIG SET auto_mode auto",
            "error: bad-argument auto_mode takes one of paper|gated|boost|closed",
        ),
        (
            "CONFIG SET auto_mode 1",
            "error: bad-argument auto_mode takes one of",
        ),
        (
            "CONFIG SET tca_self_bend 0.5",
            "error: bad-argument tca_self_bend takes one of 0|1",
        ),
        (
            "CONFIG SET aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa 1",
            "error: bad-argument CONFIG SET: no setting has so long a name",
        ),
    ];
    for (line, want) in cases {
        let r = b.send(line);
        assert_eq!(r.len(), 1, "{line}: {r:?}");
        assert!(r[0].starts_with(want), "{line}: {}", r[0]);
        assert_eq!(listing(&mut b), before, "{line} changed a setting");
    }
    assert_eq!(*b.rig.ctrl.settings(), Settings::DEFAULT);
}

#[test]
fn config_set_and_reset_change_the_live_values() {
    let mut b = Bench::new();
    assert_eq!(
        b.send("config set LOCK_TIMEOUT_S 300.46"),
        ["ok lock_timeout_s=300.5 saved=no"]
    );
    // What runs is what CONFIG shows.
    assert_eq!(b.rig.ctrl.settings().morph.lock_timeout_s, 300.5);
    assert_eq!(
        b.send("CONFIG SET auto_mode Gated"),
        ["ok auto_mode=gated saved=no"]
    );
    assert_eq!(b.send("CONFIG RESET"), ["ok config=defaults saved=no"]);
    assert_eq!(*b.rig.ctrl.settings(), Settings::DEFAULT);
}

#[test]
fn settings_cannot_change_or_be_saved_while_a_morph_runs() {
    let mut b = with_flash(Some(SimFlash::new()));
    assert_eq!(b.send("MORPH 38"), ["ok"]);
    b.run_for(1.0);
    assert!(b.rig.ctrl.busy());
    for line in ["CONFIG SET lock_timeout_s 300", "CONFIG RESET", "SAVE"] {
        let r = b.send(line);
        assert_eq!(r.len(), 1, "{r:?}");
        assert!(
            r[0].starts_with(
                "error: busy settings stay as they are while a morph, TUNE or HEAT runs (phase soften)"
            ),
            "{line}: {}",
            r[0]
        );
    }
    assert_eq!(b.rig.saves(), 0);
    assert_eq!(*b.rig.ctrl.settings(), Settings::DEFAULT);
    // CONFIG (read-only) still answers.
    assert_eq!(listing(&mut b).len(), 25);
    assert_eq!(b.send("ABORT"), ["ok"]);
    assert_eq!(
        b.send("CONFIG SET lock_timeout_s 300"),
        ["ok lock_timeout_s=300.0 saved=no"]
    );
}

#[test]
fn settings_cannot_change_or_be_saved_while_a_tune_or_a_heat_pulse_runs() {
    // A flash erase may stall the CPU past a control tick: SAVE only with the heaters off.
    for start in ["TUNE", "HEAT pla 0.5 20"] {
        let mut b = with_flash(Some(SimFlash::new()));
        b.run_for(2.0);
        let r = b.send(start);
        assert!(r[0].starts_with("ok"), "{start}: {r:?}");
        b.run_for(1.0);
        assert!(b.rig.ctrl.busy(), "{start}");
        for line in ["CONFIG SET lock_timeout_s 300", "CONFIG RESET", "SAVE"] {
            let r = b.send(line);
            assert!(
                r[0].starts_with(
                    "error: busy settings stay as they are while a morph, TUNE or HEAT runs"
                ),
                "{start}, {line}: {r:?}"
            );
        }
        assert_eq!(b.rig.saves(), 0, "{start}");
        assert_eq!(*b.rig.ctrl.settings(), Settings::DEFAULT, "{start}");
        assert_eq!(b.send("ABORT"), ["ok"]);
        assert!(!b.rig.ctrl.busy(), "{start}");
        assert!(b.send("SAVE")[0].starts_with("ok saved"), "{start}");
    }
}

#[test]
fn save_without_storage_is_unsupported() {
    let mut b = Bench::new();
    let r = b.send("SAVE");
    assert_eq!(r.len(), 1);
    assert!(
        r[0].starts_with("error: unsupported SAVE needs settings storage"),
        "{}",
        r[0]
    );
}

#[test]
fn saved_settings_survive_a_reboot_and_unsaved_ones_do_not() {
    let mut b = with_flash(Some(SimFlash::new()));
    assert!(b
        .lines
        .contains(&"event: config defaults reason=absent".to_string()));
    b.send("CONFIG SET soften_timeout_s 45");
    b.send("CONFIG SET auto_mode boost");
    let r = b.send("SAVE");
    assert_eq!(r, ["ok saved bytes=106 erases=0"]);
    b.send("CONFIG SET bend_timeout_s 200");
    let flash = b.rig.flash().unwrap().clone();

    let again = with_flash(Some(flash));
    assert!(
        again
            .lines
            .contains(&"event: config loaded settings=25".to_string()),
        "{:?}",
        again.lines
    );
    let s = again.rig.ctrl.settings().morph;
    assert_eq!((s.soften_timeout_s, s.bend_timeout_s), (45.0, 120.0));
    assert_eq!(s.auto_mode, morphlink::protocol::Mode::Boost);
    // And the boot heated nothing.
    assert_eq!(again.phase(), Phase::Idle);
    assert_eq!(again.rig.ctrl.outputs(), Outputs::IDLE);
}

/// A good blob's bytes.
fn good_blob() -> Vec<u8> {
    let mut s = Settings::DEFAULT;
    s.set_text("lock_timeout_s", "200").unwrap();
    codec::encode(&s).as_bytes().to_vec()
}

/// Re-seals a hand-made body with a valid CRC-32 (ISO-HDLC), as a blob from another firmware.
fn sealed(body: &[u8]) -> Vec<u8> {
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(body);
    let mut v = body.to_vec();
    v.extend_from_slice(&crc.to_le_bytes());
    v
}

#[test]
fn bad_stored_settings_boot_as_the_defaults_with_the_reason_and_never_heat() {
    let good = good_blob();
    let body = &good[..good.len() - 4];
    let mut corrupt = good.clone();
    corrupt[10] ^= 0x40;
    let mut old = body.to_vec();
    old[0] = 0;
    let mut out_of_range = body.to_vec();
    out_of_range[2 + 24..2 + 28].copy_from_slice(&5000.0f32.to_le_bytes());
    let cases: Vec<(&str, Option<SimFlash>, &str)> = vec![
        ("absent", Some(SimFlash::new()), "reason=absent"),
        (
            "corrupt",
            Some(flash_holding(&corrupt)),
            "reason=crc-mismatch",
        ),
        (
            "truncated",
            Some(flash_holding(&good[..20])),
            "reason=truncated",
        ),
        (
            "older format",
            Some(flash_holding(&sealed(&old))),
            "reason=old-format",
        ),
        (
            "out of range",
            Some(flash_holding(&sealed(&out_of_range))),
            "reason=out-of-range setting=lock_timeout_s",
        ),
        ("unreadable flash", None, "reason=flash-error"),
        (
            "garbage flash",
            SimFlash::from_image(&[0x5A; SIM_FLASH_BYTES]),
            "reason=",
        ),
    ];
    for (what, flash, want) in cases {
        let mut b = with_flash(flash);
        let ev: Vec<_> = b
            .lines
            .iter()
            .filter(|l| l.starts_with("event: config"))
            .cloned()
            .collect();
        assert_eq!(ev.len(), 1, "{what}: {ev:?}");
        assert!(
            ev[0].starts_with("event: config defaults ") && ev[0].contains(want),
            "{what}: {}",
            ev[0]
        );
        assert_eq!(*b.rig.ctrl.settings(), Settings::DEFAULT, "{what}");
        b.run_for(5.0);
        assert_eq!(b.phase(), Phase::Idle, "{what}");
        assert_eq!(b.rig.ctrl.outputs(), Outputs::IDLE, "{what}: heated");
        // And SAVE recovers: the next boot loads.
        assert!(b.send("SAVE")[0].starts_with("ok saved"), "{what}");
        let again = with_flash(Some(b.rig.flash().unwrap().clone()));
        assert!(
            again
                .lines
                .contains(&"event: config loaded settings=25".to_string()),
            "{what}: {:?}",
            again.lines
        );
    }
    // The decode the boot ran is the codec's.
    assert_eq!(codec::decode(&good[..20]), Err(LoadError::Truncated));
}

/// The boot's `event: config ...` line, after booting `flash`, and the settings it put in force.
fn boot_event(flash: SimFlash) -> (String, Settings) {
    let b = with_flash(Some(flash));
    let ev: Vec<_> = b
        .lines
        .iter()
        .filter(|l| l.starts_with("event: config"))
        .cloned()
        .collect();
    assert_eq!(ev.len(), 1, "{ev:?}");
    (ev[0].clone(), *b.rig.ctrl.settings())
}

/// sequential-storage's item header, bytes: data CRC, length, length CRC.
const ITEM_HEADER_BYTES: usize = 8;

/// `CONFIG SET <set>` and a SAVE on `b`; the flash image before and after it.
fn save_on(b: &mut Bench, set: &str) -> (Vec<u8>, Vec<u8>) {
    let before = b.rig.flash().unwrap().image().to_vec();
    assert!(b.send(&format!("CONFIG SET {set}"))[0].starts_with("ok"));
    assert!(b.send("SAVE")[0].starts_with("ok saved"));
    (before, b.rig.flash().unwrap().image().to_vec())
}

/// What a SAVE turned `before` into `after` wrote after the settings blob's item header:
/// the item's first byte, the end of its header, key and blob (what the map's CRCs cover),
/// and the end of all the SAVE wrote (its save record too). The item is the first written
/// word whose header's length field is the key (1 byte) and the 90-byte blob.
fn newest_item(before: &[u8], after: &[u8]) -> (usize, usize, usize) {
    let blob_len = codec::encode(&Settings::DEFAULT).as_bytes().len();
    let len = ((1 + blob_len) as u16).to_le_bytes();
    let written = |i: &usize| before[*i] == 0xFF && after[*i] != 0xFF;
    let end = (0..after.len()).rev().find(written).unwrap() + 1;
    let start = (0..after.len())
        .step_by(8)
        .filter(written)
        .find(|&i| after[i + 4..i + 6] == len)
        .unwrap();
    (start, start + ITEM_HEADER_BYTES + 1 + blob_len, end)
}

/// Byte flips tried at each position: one low bit, every bit.
const FLIPS: [u8; 2] = [0x01, 0xFF];

#[test]
fn a_damaged_newest_save_never_boots_the_older_values_silently() {
    let mut older = Settings::DEFAULT;
    older.set_text("lock_timeout_s", "300").unwrap();
    let mut newer = older;
    newer.set_text("lock_timeout_s", "400").unwrap();
    let mut b = with_flash(Some(SimFlash::new()));
    save_on(&mut b, "lock_timeout_s 300");
    let (before, after) = save_on(&mut b, "lock_timeout_s 400");
    let (start, checked_end, end) = newest_item(&before, &after);
    let mut previous = 0;
    for at in start..end {
        for flip in FLIPS {
            let mut image = after.clone();
            image[at] ^= flip;
            let (event, settings) = boot_event(SimFlash::from_image(&image).unwrap());
            if settings == newer {
                // The flip missed what the map checks (word padding, the record): newest.
                assert_eq!(event, "event: config loaded settings=25", "byte {at}");
            } else {
                assert_eq!(settings, older, "byte {at} ^ {flip:#x}: {event}");
                assert_eq!(
                    event, "event: config loaded settings=25 save=previous reason=crc-mismatch",
                    "byte {at} ^ {flip:#x}"
                );
                previous += 1;
            }
            if at < checked_end {
                assert_eq!(settings, older, "byte {at} ^ {flip:#x} of the newest blob");
            }
        }
    }
    assert!(previous >= (checked_end - start) * FLIPS.len());
}

#[test]
fn a_damaged_only_save_boots_the_defaults_as_crc_mismatch_not_absent() {
    let mut saved = Settings::DEFAULT;
    saved.set_text("bend_timeout_s", "200").unwrap();
    let mut b = with_flash(Some(SimFlash::new()));
    let (before, after) = save_on(&mut b, "bend_timeout_s 200");
    let (start, checked_end, end) = newest_item(&before, &after);
    for at in start..end {
        for flip in FLIPS {
            let mut image = after.clone();
            image[at] ^= flip;
            let (event, settings) = boot_event(SimFlash::from_image(&image).unwrap());
            assert_ne!(event, "event: config defaults reason=absent", "byte {at}");
            if at < checked_end || settings != saved {
                assert_eq!(
                    (event.as_str(), settings),
                    (
                        "event: config defaults reason=crc-mismatch",
                        Settings::DEFAULT
                    ),
                    "byte {at} ^ {flip:#x}"
                );
            } else {
                assert_eq!(event, "event: config loaded settings=25", "byte {at}");
            }
        }
    }
    // `absent` is what an area that never held a SAVE boots as.
    let (event, _) = boot_event(SimFlash::from_image(&before).unwrap());
    assert_eq!(event, "event: config defaults reason=absent");
}

/// Bend's start, s after MORPH, from the `event: phase bend` line.
fn bend_start_s(b: &Bench, from: usize) -> f64 {
    b.lines[from..]
        .iter()
        .find_map(|l| l.strip_prefix("event: phase bend t="))
        .and_then(|r| r.split(' ').next())
        .and_then(|t| t.parse().ok())
        .expect("a bend phase")
}

#[test]
fn the_live_soft_threshold_ends_soften_on_both_plants() {
    for link in LINKS {
        for mode in ["gated", "closed"] {
            let mut default = Bench::on(link);
            let from = default.lines.len();
            default.morph(38.0, mode);
            let t_default = bend_start_s(&default, from);

            let mut lower = Bench::on(link);
            assert_eq!(
                lower.send("CONFIG SET soft_threshold_c 64"),
                ["ok soft_threshold_c=64.0 saved=no"]
            );
            let from = lower.lines.len();
            lower.morph(38.0, mode);
            let t_lower = bend_start_s(&lower, from);
            assert!(
                t_lower < t_default - 0.2,
                "{link:?} {mode}: soften ended at {t_lower} s with 64 C, {t_default} s with 70 C"
            );
        }
    }
}

#[test]
fn the_live_auto_mode_picks_the_strategy() {
    // `paper` keeps its fixed 20 s soften whatever the PLA reads; `closed` (the default)
    // ends it in a few seconds under water.
    let link = Link::Lumped;
    let mut b = Bench::on(link);
    let from = b.lines.len();
    b.morph(38.0, "auto");
    assert!(bend_start_s(&b, from) < 15.0);
    let mut b = Bench::on(link);
    b.send("CONFIG SET auto_mode paper");
    let from = b.lines.len();
    b.send("MORPH 38");
    b.run_until(400.0, |b| !b.rig.ctrl.busy());
    assert!((bend_start_s(&b, from) - 20.0).abs() < 0.3);
}
