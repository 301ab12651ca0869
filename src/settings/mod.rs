//! The named settings: every value a user may change on the device, with its unit, default,
//! allowed range and a one-line doc, in one registry (`CONFIG` lists it, `CONFIG SET` changes
//! it, `SAVE` keeps it in flash through [`store`]).
//!
//! Settings come in groups ([`Group`]): plain structs of values with a table of [`Spec`]s and
//! get/set by index. The registry ([`Settings`]) is the list of groups; adding a group is a field
//! in [`Settings`], one line in each of [`Settings::groups`] and [`Settings::groups_mut`], and a
//! new [`codec::FORMAT_VERSION`] (the stored layout changed).
//!
//! The hard safety limits (the supervisor's temperature limits, supply bounds, heater caps) are
//! not settings: the supervisor reads its own constants, and every setting's range lies inside
//! them (the `const` assertions below), so no value a user can set widens a limit.

pub mod codec;
pub mod ram_flash;
pub mod save_record;
pub mod store;

use crate::calibration::{Calibration, CONVECTION_FIELD, FIELDS, FIELD_COUNT};
use crate::link::LINK;
use crate::part_limit::{CEILING_BAND_K, CEILING_MARGIN_K, UNTUNED_BEAD_SHARES};
use crate::protocol::Mode;
use crate::sequencer::{PhaseTimeouts, BEND_TIMEOUT_S, LOCK_TIMEOUT_S, SOFTEN_TIMEOUT_S};
use crate::strategy::closed::CLOSED_RIGID_COOL_C;
use crate::strategy::model::{MODEL_GUARD_K, PLA_SOFT_TARGET_C};
use crate::strategy::{Thresholds, AUTO_STRATEGY, RIGID_THRESHOLD_C, SOFT_THRESHOLD_C};
use crate::supervisor::{HEATER_VERDICT_S, PLA_LIMITS, TCA_LIMITS};

/// One setting: its wire name, unit, default, allowed range and doc.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spec {
    /// Wire name (snake_case, the unit as its suffix where it has one).
    pub name: &'static str,
    /// Unit as `CONFIG` shows it (`s`, `C`, `W`, ...; `-` for a choice).
    pub unit: &'static str,
    /// Compiled-in value (for a choice: the index into [`Spec::choices`]).
    pub default: f32,
    /// Smallest allowed value.
    pub min: f32,
    /// Largest allowed value.
    pub max: f32,
    /// Decimals `CONFIG` shows.
    pub decimals: u8,
    /// For a choice, its words (the value is an index); empty for a number.
    pub choices: &'static [&'static str],
    /// One line: what it does (for the host's tools and docs; empty in the firmware, which
    /// never shows it: [`crate::calibration::doc_text`]).
    pub doc: &'static str,
}

impl Spec {
    /// A number setting.
    pub const fn number(
        name: &'static str,
        unit: &'static str,
        default: f32,
        (min, max): (f32, f32),
        decimals: u8,
        doc: &'static str,
    ) -> Spec {
        Spec {
            name,
            unit,
            default,
            min,
            max,
            decimals,
            choices: &[],
            doc: crate::calibration::doc_text(doc),
        }
    }

    /// True if `v` is allowed (finite, within `min..=max`, and a whole index for a choice).
    pub fn allows(&self, v: f32) -> bool {
        v.is_finite()
            && v >= self.min
            && v <= self.max
            && (self.choices.is_empty() || v == (v as u32) as f32)
    }

    /// The word of choice value `v` (None for a number setting or an index out of range).
    pub fn choice_word(&self, v: f32) -> Option<&'static str> {
        if self.choices.is_empty() || !self.allows(v) {
            return None;
        }
        self.choices.get(v as usize).copied()
    }
}

/// A group of settings: a plain struct of values with a [`Spec`] per value, read and written
/// by index. Values handed to [`Group::set`] have passed [`Spec::allows`].
pub trait Group {
    /// One spec per value, in index order.
    fn specs(&self) -> &'static [Spec];
    /// Value `i`.
    fn get(&self, i: usize) -> f32;
    /// Sets value `i` (already range-checked).
    fn set(&mut self, i: usize, v: f32);
}

/// The words of [`MorphSettings::auto_mode`], in index order.
pub const AUTO_MODE_CHOICES: [&str; 4] = ["paper", "gated", "boost", "closed"];
const AUTO_MODES: [Mode; 4] = [Mode::Paper, Mode::Gated, Mode::Boost, Mode::Closed];

const fn mode_index(m: Mode) -> usize {
    match m {
        Mode::Paper => 0,
        Mode::Gated => 1,
        Mode::Boost => 2,
        Mode::Closed | Mode::Auto => 3,
    }
}

/// Allowed soften timeout, s: above the heater check's window (a dead heater trips before its
/// phase can time out) and at most twice the default.
pub const SOFTEN_TIMEOUT_RANGE_S: (f32, f32) = (HEATER_VERDICT_S + 10.0, 120.0);
/// Allowed bend timeout, s: the slowest healthy bend settles in about 40 s.
pub const BEND_TIMEOUT_RANGE_S: (f32, f32) = (30.0, 300.0);
/// Allowed lock timeout, s: lock takes about 15 s under water and minutes in still air.
pub const LOCK_TIMEOUT_RANGE_S: (f32, f32) = (30.0, 900.0);
/// Allowed soft threshold, °C: from 2 K to 8 K above the PLA's 62 °C glass transition (the
/// lagging thermistor must not call the rod soft before it is), and so above `closed`'s
/// rigid-cool threshold.
pub const SOFT_THRESHOLD_RANGE_C: (f32, f32) = (64.0, 70.0);
/// Allowed rigid threshold, °C: at most `closed`'s rigid-cool threshold, at least 10 K above
/// a warm bath.
pub const RIGID_THRESHOLD_RANGE_C: (f32, f32) = (35.0, CLOSED_RIGID_COOL_C);
/// Allowed PLA target of the model strategies, °C: at least 5 K above the highest soft
/// threshold, and at most the reading whose rod estimate is where the rod's ceiling begins to
/// scale its heater down, in the link file's bath ([`crate::part_limit::reachable_c`]); above it
/// the ceiling would hold the heater down before the target, so no such target can be reached (what the range guarantees, and on which links: docs/settings.md).
pub const PLA_SOFT_TARGET_RANGE_C: (f32, f32) = (SOFT_THRESHOLD_RANGE_C.1 + 5.0, PLA_TARGET_MAX_C);
/// The top of [`PLA_SOFT_TARGET_RANGE_C`], °C: `22 + 0.7 × (130 − 15 − 5 − 22)`
/// ([`crate::part_limit::reachable_c`] of an untuned link), rounded down to the tenth `CONFIG`
/// prints.
const PLA_TARGET_MAX_C: f32 = {
    let amb = LINK.surroundings.ambient_c as f32;
    let ceiling = PLA_LIMITS.max_c - CEILING_MARGIN_K - CEILING_BAND_K;
    let t = amb + UNTUNED_BEAD_SHARES[0] * (ceiling - amb);
    (t * 10.0) as i32 as f32 / 10.0
};
const _: () = assert!(PLA_TARGET_MAX_C > SOFT_THRESHOLD_RANGE_C.1 + 5.0);

// The hard limits bound every range: no setting can reach a trip limit or widen it.
const _: () = assert!(PLA_SOFT_TARGET_RANGE_C.1 + MODEL_GUARD_K + 10.0 <= PLA_LIMITS.max_c);
const _: () = assert!(SOFT_THRESHOLD_RANGE_C.1 + 5.0 <= PLA_SOFT_TARGET_RANGE_C.0);
const _: () = assert!(RIGID_THRESHOLD_RANGE_C.1 < SOFT_THRESHOLD_RANGE_C.0);
const _: () = assert!(CLOSED_RIGID_COOL_C < SOFT_THRESHOLD_RANGE_C.0);
const _: () = assert!(RIGID_THRESHOLD_RANGE_C.0 > PLA_LIMITS.min_c);
const _: () = assert!(PLA_SOFT_TARGET_RANGE_C.1 < TCA_LIMITS.max_c);
const _: () = assert!(SOFTEN_TIMEOUT_RANGE_S.0 > HEATER_VERDICT_S);

/// The morph's settings: what `auto` runs, the phase thresholds and the phase timeouts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MorphSettings {
    /// The strategy `MORPH <r>` and `MORPH <r> auto` run.
    pub auto_mode: Mode,
    /// PLA temperature at which soften ends, °C.
    pub soft_threshold_c: f32,
    /// PLA temperature at which lock ends, °C.
    pub rigid_threshold_c: f32,
    /// PLA temperature `boost` and `closed` hold the rod at, °C.
    pub pla_soft_target_c: f32,
    /// Soften timeout, s.
    pub soften_timeout_s: f32,
    /// Bend timeout, s.
    pub bend_timeout_s: f32,
    /// Lock timeout, s.
    pub lock_timeout_s: f32,
}

/// The specs of [`MorphSettings`], in its index order.
pub const MORPH_SPECS: [Spec; 7] = [
    Spec {
        name: "auto_mode",
        unit: "-",
        default: mode_index(AUTO_STRATEGY) as f32,
        min: 0.0,
        max: (AUTO_MODE_CHOICES.len() - 1) as f32,
        decimals: 0,
        choices: &AUTO_MODE_CHOICES,
        doc: crate::calibration::doc_text("strategy MORPH runs without a mode and with auto"),
    },
    Spec::number(
        "soft_threshold_c",
        "C",
        SOFT_THRESHOLD_C,
        SOFT_THRESHOLD_RANGE_C,
        1,
        "PLA temperature that ends soften",
    ),
    Spec::number(
        "rigid_threshold_c",
        "C",
        RIGID_THRESHOLD_C,
        RIGID_THRESHOLD_RANGE_C,
        1,
        "PLA temperature that ends lock",
    ),
    Spec::number(
        "pla_soft_target_c",
        "C",
        PLA_SOFT_TARGET_C,
        PLA_SOFT_TARGET_RANGE_C,
        1,
        "PLA temperature boost and closed hold during soften and bend",
    ),
    Spec::number(
        "soften_timeout_s",
        "s",
        SOFTEN_TIMEOUT_S,
        SOFTEN_TIMEOUT_RANGE_S,
        1,
        "soften longer than this is a phase-timeout fault",
    ),
    Spec::number(
        "bend_timeout_s",
        "s",
        BEND_TIMEOUT_S,
        BEND_TIMEOUT_RANGE_S,
        1,
        "bend longer than this is a phase-timeout fault",
    ),
    Spec::number(
        "lock_timeout_s",
        "s",
        LOCK_TIMEOUT_S,
        LOCK_TIMEOUT_RANGE_S,
        1,
        "lock longer than this is a phase-timeout fault",
    ),
];

impl MorphSettings {
    /// The compiled-in values.
    pub const DEFAULT: MorphSettings = MorphSettings {
        auto_mode: AUTO_STRATEGY,
        soft_threshold_c: SOFT_THRESHOLD_C,
        rigid_threshold_c: RIGID_THRESHOLD_C,
        pla_soft_target_c: PLA_SOFT_TARGET_C,
        soften_timeout_s: SOFTEN_TIMEOUT_S,
        bend_timeout_s: BEND_TIMEOUT_S,
        lock_timeout_s: LOCK_TIMEOUT_S,
    };

    /// The thresholds a morph runs with.
    pub fn thresholds(&self) -> Thresholds {
        Thresholds {
            soft_threshold_c: self.soft_threshold_c,
            rigid_threshold_c: self.rigid_threshold_c,
            pla_soft_target_c: self.pla_soft_target_c,
        }
    }

    /// The phase timeouts a morph runs with.
    pub fn timeouts(&self) -> PhaseTimeouts {
        PhaseTimeouts {
            soften_s: self.soften_timeout_s,
            bend_s: self.bend_timeout_s,
            lock_s: self.lock_timeout_s,
        }
    }

    /// The strategy `mode` runs (`auto` resolved to [`MorphSettings::auto_mode`]).
    pub fn resolve(&self, mode: Mode) -> Mode {
        match mode {
            Mode::Auto => self.auto_mode,
            m => m,
        }
    }
}

impl Group for MorphSettings {
    fn specs(&self) -> &'static [Spec] {
        &MORPH_SPECS
    }

    fn get(&self, i: usize) -> f32 {
        match i {
            0 => mode_index(self.auto_mode) as f32,
            1 => self.soft_threshold_c,
            2 => self.rigid_threshold_c,
            3 => self.pla_soft_target_c,
            4 => self.soften_timeout_s,
            5 => self.bend_timeout_s,
            6 => self.lock_timeout_s,
            _ => f32::NAN,
        }
    }

    fn set(&mut self, i: usize, v: f32) {
        match i {
            0 => self.auto_mode = AUTO_MODES[(v as usize).min(AUTO_MODES.len() - 1)],
            1 => self.soft_threshold_c = v,
            2 => self.rigid_threshold_c = v,
            3 => self.pla_soft_target_c = v,
            4 => self.soften_timeout_s = v,
            5 => self.bend_timeout_s = v,
            6 => self.lock_timeout_s = v,
            _ => {}
        }
    }
}

/// How many groups [`Settings`] has.
pub const GROUPS: usize = 2;

/// Decimals `CONFIG` shows for a calibration value (they are stored exactly, as `f32`).
pub const CALIBRATION_DECIMALS: u8 = 3;

/// Calibration fields that are settings: all but the last, its layout `version`, which the
/// stored form's own [`codec::FORMAT_VERSION`] covers (a setting with one allowed value is none).
pub const CALIBRATION_SETTINGS: usize = FIELD_COUNT - 1;
const _: () = assert!(
    matches!(FIELDS[CALIBRATION_SETTINGS].name.as_bytes(), b"version"),
    "the calibration's last field is its layout version"
);

/// The calibration's settings: one per [`FIELDS`] row but the version (`TUNE` and `MEASURED`
/// write them, `SAVE` keeps them), each defaulting to the compiled-in link's value.
pub const CALIBRATION_SPECS: [Spec; CALIBRATION_SETTINGS] = {
    let mut specs = [Spec::number("", "", 0.0, (0.0, 0.0), 0, ""); CALIBRATION_SETTINGS];
    let mut i = 0;
    while i < CALIBRATION_SETTINGS {
        let f = FIELDS[i];
        let choices: &[&str] = match i {
            crate::calibration::SELF_BEND_FIELD => &crate::calibration::SWITCH_CHOICES,
            _ => &[],
        };
        specs[i] = Spec {
            choices,
            ..Spec::number(
                f.name,
                f.unit,
                Calibration::DEFAULT.value(i),
                (f.min, f.max),
                CALIBRATION_DECIMALS,
                f.doc,
            )
        };
        i += 1;
    }
    specs
};

impl Group for Calibration {
    fn specs(&self) -> &'static [Spec] {
        &CALIBRATION_SPECS
    }
    fn get(&self, i: usize) -> f32 {
        self.value(i)
    }
    fn set(&mut self, i: usize, v: f32) {
        // The registry has range-checked `v` against the same row; a refusal changes nothing.
        let _ = Calibration::set(self, i, v);
    }
}

/// Every setting the device has, in groups. [`Settings::DEFAULT`] is the compiled-in set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// What a morph runs with.
    pub morph: MorphSettings,
    /// This link's calibration (`TUNE`, `MEASURED`).
    pub cal: Calibration,
}

/// Where one setting sits in the registry: its group and its index in the group.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SettingId {
    /// Group index (order of [`Settings::groups`]).
    pub group: usize,
    /// Index in the group.
    pub index: usize,
}

/// Why `CONFIG SET` refused a value (nothing was changed).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SetError {
    /// No setting has that name.
    UnknownName,
    /// The value is not a number (or, for a choice, not one of its words).
    Malformed(Spec),
    /// The value is outside the setting's range.
    OutOfRange(Spec, f32),
    /// The value is in range, but it leaves the calibration's rises out of line with the model
    /// at its convection (the rule `TUNE` is held to).
    Inconsistent(Spec, f32, crate::calibration::Inconsistent),
}

impl Default for Settings {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl Settings {
    /// The compiled-in values.
    pub const DEFAULT: Settings = Settings {
        morph: MorphSettings::DEFAULT,
        cal: Calibration::DEFAULT,
    };

    /// The groups, in registry (and storage) order.
    pub fn groups(&self) -> [&dyn Group; GROUPS] {
        [&self.morph, &self.cal]
    }

    /// The groups, mutable, in the same order.
    pub fn groups_mut(&mut self) -> [&mut dyn Group; GROUPS] {
        [&mut self.morph, &mut self.cal]
    }

    /// Every setting with its current value, in registry order.
    pub fn for_each(&self, mut f: impl FnMut(&Spec, f32)) {
        for g in self.groups() {
            for (i, spec) in g.specs().iter().enumerate() {
                f(&self.live(*spec), g.get(i));
            }
        }
    }

    /// `spec` with the range a value may have now: a calibration rise's range narrowed to the
    /// shares [`crate::calibration::SHARE_RULE`] allows of the model's rise at the live
    /// `convection_w_m2k` (rounded inwards to the decimals shown), so every value inside the
    /// printed range is accepted and keeps the calibration consistent.
    pub fn live(&self, spec: Spec) -> Spec {
        use crate::calibration::SHARE_RULE;
        if spec.name.as_bytes() == FIELDS[CONVECTION_FIELD].name.as_bytes() {
            return self.live_convection(spec);
        }
        let Some(k) = SHARE_RULE
            .iter()
            .position(|&(i, _)| FIELDS[i].name.as_bytes() == spec.name.as_bytes())
        else {
            return spec;
        };
        let r = self.cal.model_resistances();
        let model = [r.r_pp, r.r_tt, r.r_tp, r.r_tp][k];
        let (lo, hi) = SHARE_RULE[k].1;
        let scale = decimal_scale(spec.decimals);
        let min = (whole(lo * model * scale) + 1.0) / scale;
        let max = whole(hi * model * scale) / scale;
        Spec {
            min: spec.min.max(if lo == 0.0 { 0.0 } else { min }),
            max: spec.max.min(max),
            ..spec
        }
    }

    /// `spec` (the convection's) narrowed to the convections at which the live rises keep
    /// [`crate::calibration::SHARE_RULE`]: every share grows with the convection (the model's
    /// rises fall), so the allowed values are one interval, found by bisection and rounded
    /// inwards to the decimals shown.
    fn live_convection(&self, spec: Spec) -> Spec {
        let ok = |h: f32| {
            let mut c = self.cal;
            c.convection_w_m2k = h;
            c.share_rule().is_ok()
        };
        let now = self.cal.convection_w_m2k;
        if !ok(now) || !spec.allows(now) {
            return spec;
        }
        let step = 1.0 / decimal_scale(spec.decimals);
        // Bisects between an allowed `inside` and a refused `outside`.
        let edge = |mut inside: f32, mut outside: f32| {
            for _ in 0..40 {
                let mid = 0.5 * (inside + outside);
                if ok(mid) {
                    inside = mid;
                } else {
                    outside = mid;
                }
            }
            inside
        };
        let min = if ok(spec.min) {
            spec.min
        } else {
            let mut m = round_to(edge(now, spec.min) + 0.5 * step, spec.decimals);
            while !ok(m) && m < now {
                m = round_to(m + step, spec.decimals);
            }
            m
        };
        let max = if ok(spec.max) {
            spec.max
        } else {
            let mut m = round_to(edge(now, spec.max) - 0.5 * step, spec.decimals);
            while !ok(m) && m > now {
                m = round_to(m - step, spec.decimals);
            }
            m
        };
        Spec { min, max, ..spec }
    }

    /// How many settings there are.
    pub fn count(&self) -> usize {
        self.groups().iter().map(|g| g.specs().len()).sum()
    }

    /// The setting named `name` (ASCII case ignored).
    pub fn find(&self, name: &str) -> Option<(SettingId, Spec)> {
        for (group, g) in self.groups().iter().enumerate() {
            for (index, spec) in g.specs().iter().enumerate() {
                if spec.name.eq_ignore_ascii_case(name) {
                    return Some((SettingId { group, index }, self.live(*spec)));
                }
            }
        }
        None
    }

    /// The value of `id`.
    pub fn get(&self, id: SettingId) -> f32 {
        self.groups()[id.group].get(id.index)
    }

    /// Sets `name` from its wire text `value` (a decimal number, or for a choice one of its
    /// words); refuses an unknown name, a malformed value or one out of range and then changes
    /// nothing. Returns the setting's spec and the value now set.
    // The error carries the spec so the reply can name the setting's range and doc: copied,
    // not boxed (no allocator).
    #[allow(clippy::result_large_err)]
    pub fn set_text(&mut self, name: &str, value: &str) -> Result<(Spec, f32), SetError> {
        let (id, spec) = self.find(name).ok_or(SetError::UnknownName)?;
        let v = if spec.choices.is_empty() {
            crate::fixed::parse_decimal(value)
                .filter(|v| v.is_finite())
                .ok_or(SetError::Malformed(spec))?
        } else {
            spec.choices
                .iter()
                .position(|w| w.eq_ignore_ascii_case(value))
                .ok_or(SetError::Malformed(spec))? as f32
        };
        // What runs is what CONFIG shows: the value rounded to the decimals shown.
        let v = round_to(v, spec.decimals);
        if !spec.allows(v) {
            return Err(SetError::OutOfRange(spec, v));
        }
        let before = self.cal;
        self.groups_mut()[id.group].set(id.index, v);
        if self.cal != before {
            if let Err(why) = self.cal.share_rule() {
                self.cal = before;
                return Err(SetError::Inconsistent(spec, v, why));
            }
        }
        Ok((spec, v))
    }
}

/// `v` rounded to `decimals` places (half away from zero), as [`crate::fixed::Fixed`] shows it.
/// 10 to the power `decimals` (at most 3: no setting shows more).
fn decimal_scale(decimals: u8) -> f32 {
    [1.0f32, 10.0, 100.0, 1000.0][(decimals as usize).min(3)]
}

fn round_to(v: f32, decimals: u8) -> f32 {
    let scale = decimal_scale(decimals);
    let x = v * scale;
    let r = if x >= 0.0 {
        whole(x + 0.5)
    } else {
        whole(x - 0.5)
    };
    if x.abs() < 1e15 {
        r / scale
    } else {
        v
    }
}

/// `x as i64 as f32` in 32-bit arithmetic, so the firmware carries no 64-bit float
/// conversions: the same value for every `x` (an `f32` beyond `i32`'s range is already whole;
/// NaN is 0 and the rest saturates as `as i64` does).
#[allow(
    clippy::manual_clamp,
    reason = "f32::clamp checks its bounds and carries a panic path into the image"
)]
fn whole(x: f32) -> f32 {
    const I64_MAX: f32 = i64::MAX as f32;
    if x.abs() < 2_147_483_520.0 {
        x as i32 as f32
    } else if x.is_nan() {
        0.0
    } else if x > I64_MAX {
        I64_MAX
    } else if x < -I64_MAX {
        -I64_MAX
    } else {
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    extern crate std;
    use std::collections::BTreeSet;

    #[test]
    fn whole_is_the_i64_round_trip() {
        let mut xs = std::vec![
            0.0f32,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -2.5,
            8_388_607.5,
            16_777_217.0
        ];
        xs.extend([
            2_147_483_520.0f32,
            2_147_483_648.0,
            -2_147_483_648.0,
            1e15,
            -1e15,
            1e19,
        ]);
        xs.extend([
            -1e19,
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ]);
        let mut v = 1.0e-3f32;
        while v < 1e20 {
            xs.extend([v, -v, v + 0.5, -(v + 0.5)]);
            v *= 1.37;
        }
        for x in xs {
            assert_eq!(whole(x).to_bits(), (x as i64 as f32).to_bits(), "{x}");
        }
    }
    use std::vec::Vec;

    /// Every setting's spec as compiled in (the widest ranges; [`Settings::live`] narrows the
    /// rises').
    fn all_specs() -> Vec<Spec> {
        MORPH_SPECS
            .iter()
            .chain(CALIBRATION_SPECS.iter())
            .copied()
            .collect()
    }

    #[test]
    fn every_default_is_within_its_range_and_every_name_is_unique() {
        let mut names = BTreeSet::new();
        for s in all_specs() {
            assert!(s.min < s.max, "{}", s.name);
            assert!(s.allows(s.default), "{} default outside its range", s.name);
            assert!(names.insert(s.name), "{} twice", s.name);
            assert!(!s.doc.is_empty() && !s.unit.is_empty(), "{}", s.name);
            assert!(s
                .name
                .bytes()
                .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'_'));
        }
        Settings::DEFAULT.for_each(|s, v| assert_eq!(v, s.default, "{}", s.name));
    }

    #[test]
    fn no_setting_is_a_hard_limit() {
        // The supervisor's named limits are not in the registry: nothing can change them.
        for s in all_specs() {
            for hard in [
                "limit",
                "supply",
                "max_power",
                "max_fraction",
                "min_fraction",
            ] {
                assert!(!s.name.contains(hard), "{} looks like a hard limit", s.name);
            }
            if s.unit == "C" {
                assert!(
                    s.max + MODEL_GUARD_K + 10.0 <= PLA_LIMITS.max_c,
                    "{}",
                    s.name
                );
                assert!(s.max < TCA_LIMITS.max_c, "{}", s.name);
            }
        }
    }

    #[test]
    fn set_refuses_bad_input_and_changes_nothing() {
        let mut s = Settings::DEFAULT;
        assert_eq!(s.set_text("no_such", "1"), Err(SetError::UnknownName));
        assert!(matches!(
            s.set_text("soften_timeout_s", "abc"),
            Err(SetError::Malformed(_))
        ));
        assert!(matches!(
            s.set_text("soften_timeout_s", "1e3"),
            Err(SetError::Malformed(_))
        ));
        assert!(matches!(
            s.set_text("soften_timeout_s", "500"),
            Err(SetError::OutOfRange(_, v)) if v == 500.0
        ));
        assert!(matches!(
            s.set_text("soften_timeout_s", "5"),
            Err(SetError::OutOfRange(..))
        ));
        assert!(matches!(
            s.set_text("auto_mode", "auto"),
            Err(SetError::Malformed(_))
        ));
        assert_eq!(s, Settings::DEFAULT);
    }

    #[test]
    fn set_changes_what_a_morph_runs_with() {
        let mut s = Settings::DEFAULT;
        s.set_text("SOFTEN_TIMEOUT_S", "45").unwrap();
        assert_eq!(s.morph.timeouts().soften_s, 45.0);
        s.set_text("auto_mode", "GATED").unwrap();
        assert_eq!(s.morph.resolve(Mode::Auto), Mode::Gated);
        assert_eq!(s.morph.resolve(Mode::Boost), Mode::Boost);
        s.set_text("rigid_threshold_c", "40.5").unwrap();
        assert_eq!(s.morph.thresholds().rigid_threshold_c, 40.5);
        // Every range end is accepted.
        for spec in all_specs() {
            for v in [spec.min, spec.max] {
                let mut s = Settings::DEFAULT;
                let (id, _) = s.find(spec.name).unwrap();
                s.groups_mut()[id.group].set(id.index, v);
                assert_eq!(s.get(id), v, "{}", spec.name);
            }
        }
    }

    #[test]
    fn the_settings_doc_names_every_setting_and_its_range() {
        let doc = include_str!("../../docs/settings.md");
        for s in all_specs() {
            let row = doc
                .lines()
                .find(|l| l.starts_with(&std::format!("| `{}` |", s.name)))
                .unwrap_or_else(|| panic!("docs/settings.md has no row for {}", s.name));
            if s.choices.is_empty() {
                let d = s.decimals as usize;
                let range = std::format!("{:.d$}–{:.d$}", s.min, s.max);
                assert!(row.contains(&range), "{}: {range} not in {row}", s.name);
                assert!(
                    row.contains(&std::format!("| {:.d$} |", s.default)),
                    "{row}"
                );
            }
        }
    }
}
