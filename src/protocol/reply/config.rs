//! Settings: CONFIG, CONFIG SET, CONFIG RESET, SAVE and the boot's config event.

use super::*;

/// Where the settings are explained; their errors point to it.
pub const SETTINGS_DOC: &str = "docs/settings.md";

/// One setting as `CONFIG` shows it (the caller copies it from the settings registry).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SettingRow<'a> {
    /// Wire name.
    pub name: &'a str,
    /// Unit (`-` for a choice).
    pub unit: &'a str,
    /// Current value (a choice's index).
    pub value: f32,
    /// Compiled-in value.
    pub default: f32,
    /// Smallest allowed value.
    pub min: f32,
    /// Largest allowed value.
    pub max: f32,
    /// Decimals to show.
    pub decimals: u8,
    /// A choice's words (empty for a number).
    pub choices: &'a [&'a str],
}

impl SettingRow<'_> {
    fn word(&self, v: f32) -> &str {
        self.choices.get(v as usize).copied().unwrap_or("?")
    }
}

/// The value `v` of `r` as the wire shows it: a number with its decimals, or a choice's word.
struct SettingValue<'a>(&'a SettingRow<'a>, f32);

impl fmt::Display for SettingValue<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.0.choices.is_empty() {
            write!(f, "{}", Fixed(self.1, self.0.decimals))
        } else {
            f.write_str(self.0.word(self.1))
        }
    }
}

/// The allowed values of `r`: `<min>..<max> <unit>` or `<word>|<word>|...`.
struct SettingRange<'a>(&'a SettingRow<'a>);

impl fmt::Display for SettingRange<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let r = self.0;
        if r.choices.is_empty() {
            let d = r.decimals;
            write!(f, "{}..{} {}", Fixed(r.min, d), Fixed(r.max, d), r.unit)
        } else {
            for (i, w) in r.choices.iter().enumerate() {
                if i > 0 {
                    f.write_str("|")?;
                }
                f.write_str(w)?;
            }
            Ok(())
        }
    }
}

/// One `CONFIG` line: `data: <name>=<value> <unit> range=<min>..<max> default=<d>`, or for a
/// choice `data: <name>=<word> choices=<a>|<b>|... default=<word>`.
pub fn config_row(l: &mut OutLine, r: &SettingRow) {
    if r.choices.is_empty() {
        data(
            l,
            format_args!(
                "{}={} {} range={}..{} default={}",
                r.name,
                SettingValue(r, r.value),
                r.unit,
                Fixed(r.min, r.decimals),
                Fixed(r.max, r.decimals),
                SettingValue(r, r.default)
            ),
        );
    } else {
        data(
            l,
            format_args!(
                "{}={} choices={} default={}",
                r.name,
                SettingValue(r, r.value),
                SettingRange(r),
                SettingValue(r, r.default)
            ),
        );
    }
}

/// The end of `CONFIG`: `ok settings=<n>`.
pub fn config_end(l: &mut OutLine, count: usize) {
    ok_with(l, format_args!("settings={count}"));
}

/// `CONFIG SET` done: `ok <name>=<value> saved=no` (SAVE keeps it across a restart).
pub fn config_set(l: &mut OutLine, r: &SettingRow) {
    ok_with(
        l,
        format_args!("{}={} saved=no", r.name, SettingValue(r, r.value)),
    );
}

/// `CONFIG RESET` done: `ok config=defaults saved=no`.
pub fn config_reset(l: &mut OutLine) {
    ok_with(l, format_args!("config=defaults saved=no"));
}

/// `CONFIG SET` of a name no setting has:
/// `error: bad-argument no setting named <name>; send CONFIG for the list (docs/settings.md)`.
pub fn config_unknown(l: &mut OutLine, name: &str) {
    error(
        l,
        ErrorCode::BadArgument,
        format_args!("no setting named {name}; send CONFIG for the list ({SETTINGS_DOC})"),
    );
}

/// `CONFIG SET` of a value that is no number (or no choice's word):
/// `error: bad-argument <name> takes <range> (docs/settings.md)`.
pub fn config_malformed(l: &mut OutLine, r: &SettingRow) {
    let what = if r.choices.is_empty() {
        "a number in"
    } else {
        "one of"
    };
    error(
        l,
        ErrorCode::BadArgument,
        format_args!(
            "{} takes {what} {} ({SETTINGS_DOC})",
            r.name,
            SettingRange(r)
        ),
    );
}

/// `CONFIG SET` of a value outside the range:
/// `error: out-of-range <name>=<v> <unit> is outside <min>..<max> <unit> (docs/settings.md)`.
pub fn config_out_of_range(l: &mut OutLine, r: &SettingRow, v: f32) {
    error(
        l,
        ErrorCode::OutOfRange,
        format_args!(
            "{}={} {} is outside {} ({SETTINGS_DOC})",
            r.name,
            Fixed(v, r.decimals.max(1)),
            r.unit,
            SettingRange(r)
        ),
    );
}

/// `CONFIG SET` of a calibration value that leaves a rise out of line with the model:
/// `error: out-of-range <name>=<v> <unit> puts <field> at <share>x the model's rise at
/// convection_w_m2k=<h>, outside <lo>..<hi>x (docs/settings.md)`.
pub fn config_inconsistent(
    l: &mut OutLine,
    r: &SettingRow,
    v: f32,
    why: &crate::calibration::Inconsistent,
    convection_w_m2k: f32,
) {
    error(
        l,
        ErrorCode::OutOfRange,
        format_args!(
            "{}={} {} puts {} at {}x the model's rise at convection_w_m2k={}, outside {}..{}x ({SETTINGS_DOC})",
            r.name,
            Fixed(v, r.decimals.max(1)),
            r.unit,
            why.field.name,
            Fixed(why.share, 2),
            Fixed(convection_w_m2k, 1),
            Fixed(why.allowed.0, 1),
            Fixed(why.allowed.1, 1)
        ),
    );
}

/// `CONFIG SET`, `CONFIG RESET` or `SAVE` while a morph runs:
/// `error: busy settings stay as they are while a morph, TUNE or HEAT runs (phase <p>); ABORT or
/// wait for done`.
pub fn config_busy(l: &mut OutLine, phase: Phase) {
    error(
        l,
        ErrorCode::Busy,
        format_args!(
            "settings stay as they are while a morph, TUNE or HEAT runs (phase {}); ABORT or wait for done",
            phase.as_str()
        ),
    );
}

/// `SAVE` done: `ok saved bytes=<n> erases=<n>` (the blob's size and the pages it erased).
pub fn saved(l: &mut OutLine, bytes: u32, erases: u32) {
    ok_with(l, format_args!("saved bytes={bytes} erases={erases}"));
}

/// `SAVE` failed: `error: storage SAVE failed (<why>); the previous settings stay in flash`.
pub fn save_failed(l: &mut OutLine, why: &str) {
    error(
        l,
        ErrorCode::Storage,
        format_args!("SAVE failed ({why}); the previous settings stay in flash"),
    );
}

/// `SAVE` on a build without settings storage.
pub const ERR_SAVE_UNSUPPORTED: ProtoError = ProtoError {
    code: ErrorCode::Unsupported,
    text: "SAVE needs settings storage and this build has none (morph-sim: --flash-file PATH)",
};

/// At boot, the stored settings were loaded: `event: config loaded settings=<n>`, or, when
/// they are the previous SAVE's because the newest is damaged (`skipped` is why),
/// `event: config loaded settings=<n> save=previous reason=<why>`: the user learns that the
/// last SAVE did not hold, rather than running older values unawares.
pub fn config_loaded_event(l: &mut OutLine, count: usize, skipped: Option<&str>) {
    let _ = write!(l, "{EVENT_TAG} config loaded settings={count}");
    if let Some(why) = skipped {
        let _ = write!(l, " save=previous reason={why}");
    }
}

/// At boot, the defaults are in force: `event: config defaults reason=<why>[ setting=<name>]`
/// (`setting` names a stored value that was out of its range).
pub fn config_defaults_event(l: &mut OutLine, reason: &str, setting: Option<&str>) {
    let _ = write!(l, "{EVENT_TAG} config defaults reason={reason}");
    if let Some(s) = setting {
        let _ = write!(l, " setting={s}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::format_error;
    use crate::protocol::reply::line;

    const TIMEOUT: SettingRow = SettingRow {
        name: "soften_timeout_s",
        unit: "s",
        value: 45.0,
        default: 60.0,
        min: 20.0,
        max: 120.0,
        decimals: 0,
        choices: &[],
    };
    const MODE: SettingRow = SettingRow {
        name: "auto_mode",
        unit: "-",
        value: 1.0,
        default: 3.0,
        min: 0.0,
        max: 3.0,
        decimals: 0,
        choices: &["paper", "gated", "boost", "closed"],
    };

    #[test]
    fn settings_lines_name_the_setting_unit_and_range() {
        assert_eq!(
            line(|l| config_row(l, &TIMEOUT)),
            "data: soften_timeout_s=45 s range=20..120 default=60"
        );
        assert_eq!(
            line(|l| config_row(l, &MODE)),
            "data: auto_mode=gated choices=paper|gated|boost|closed default=closed"
        );
        assert_eq!(
            line(|l| config_set(l, &MODE)),
            "ok auto_mode=gated saved=no"
        );
        assert_eq!(
            line(|l| config_out_of_range(l, &TIMEOUT, 500.0)),
            "error: out-of-range soften_timeout_s=500.0 s is outside 20..120 s (docs/settings.md)"
        );
        assert_eq!(
            line(|l| config_malformed(l, &MODE)),
            "error: bad-argument auto_mode takes one of paper|gated|boost|closed (docs/settings.md)"
        );
        assert_eq!(
            line(|l| config_loaded_event(l, 21, None)),
            "event: config loaded settings=21"
        );
        assert_eq!(
            line(|l| config_loaded_event(l, 21, Some("crc-mismatch"))),
            "event: config loaded settings=21 save=previous reason=crc-mismatch"
        );
        assert_eq!(
            line(|l| config_defaults_event(l, "out-of-range", Some("lock_timeout_s"))),
            "event: config defaults reason=out-of-range setting=lock_timeout_s"
        );
        for l in [
            line(|l| config_unknown(l, "x")),
            line(|l| config_busy(l, Phase::Bend)),
            line(|l| save_failed(l, "flash-error")),
            format_error(&ERR_SAVE_UNSUPPORTED),
        ] {
            assert_eq!(
                crate::protocol::classify(&l),
                crate::protocol::LineKind::Error,
                "{l}"
            );
        }
    }
}
