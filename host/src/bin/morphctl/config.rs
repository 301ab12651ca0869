//! `morphctl config [list|set NAME VALUE|reset|save]`: the device's named settings over
//! `CONFIG`, `CONFIG SET`, `CONFIG RESET` and `SAVE` (docs/settings.md). The device judges every
//! value; morphctl only sends the line and shows the answer, so its checks cannot drift from
//! the firmware's.

use crate::link::{Link, LinkError, REPLY_TIMEOUT_S};
use clap::Subcommand;
use morphlink::protocol::client::{classify, LineKind};
use std::process::ExitCode;

/// How long SAVE may take, s: a flash erase of the largest settings sector (the F401's 128 KiB)
/// takes up to 2 s, plus the reply.
pub const SAVE_TIMEOUT_S: f64 = 10.0;

/// What `morphctl config` does.
#[derive(Subcommand, Clone)]
pub enum ConfigCmd {
    /// Every setting: value, unit, allowed range, default (the default action).
    List,
    /// Set one setting (not saved: `config save` keeps it across a restart).
    Set {
        /// Setting name, as `config list` shows it.
        name: String,
        /// New value: a number in the setting's unit, or one of its choices.
        value: String,
        /// SAVE right after, if the device accepted the value.
        #[arg(long)]
        save: bool,
    },
    /// Every setting back to its default (not saved).
    Reset,
    /// Write the settings to the device's flash (refused while a morph runs).
    Save,
}

/// Runs `cmd` on `link`; an `error:` reply is a failure exit.
pub fn run(link: &mut Link, cmd: ConfigCmd) -> Result<ExitCode, String> {
    if let Some(sig) = link.signal() {
        return Err(LinkError::Interrupted(sig).into());
    }
    let (line, timeout_s) = match &cmd {
        ConfigCmd::List => ("CONFIG".to_string(), REPLY_TIMEOUT_S),
        ConfigCmd::Set { name, value, .. } => {
            (format!("CONFIG SET {name} {value}"), REPLY_TIMEOUT_S)
        }
        ConfigCmd::Reset => ("CONFIG RESET".to_string(), REPLY_TIMEOUT_S),
        ConfigCmd::Save => ("SAVE".to_string(), SAVE_TIMEOUT_S),
    };
    let (data, fin) = link.command(&line, timeout_s, &mut |l| println!("{l}"))?;
    if let ConfigCmd::List = cmd {
        print_table(&data);
    }
    let accepted = classify(&fin) == LineKind::Ok;
    if let (ConfigCmd::Set { save: true, .. }, true) = (&cmd, accepted) {
        // `saved=no` is true of the set alone; the SAVE that follows says what is stored.
        println!("{}", without_saved_no(&fin));
        let code = run(link, ConfigCmd::Save)?;
        if code == ExitCode::SUCCESS {
            println!("(saved: kept across a restart)");
        } else {
            println!("(set, but not saved: it lasts until a restart)");
        }
        return Ok(code);
    }
    println!("{fin}");
    if let (ConfigCmd::Set { .. } | ConfigCmd::Reset, true) = (&cmd, accepted) {
        println!("(not saved: `morphctl config save` keeps it across a restart)");
    }
    Ok(if classify(&fin) == LineKind::Error {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    })
}

/// A `CONFIG SET` reply without its `saved=no` (shown before the SAVE that `--save` sends).
fn without_saved_no(reply: &str) -> String {
    reply
        .split(' ')
        .filter(|w| *w != "saved=no")
        .collect::<Vec<_>>()
        .join(" ")
}

/// One `CONFIG` data line (`name=value unit range=a..b default=d`, or `name=word choices=...
/// default=word`) as table columns: name, value, unit, allowed, default.
fn columns(data: &str) -> Option<[String; 5]> {
    let mut words = data.split(' ');
    let (name, value) = words.next()?.split_once('=')?;
    let mut unit = String::new();
    let mut allowed = String::new();
    let mut default = String::new();
    for w in words {
        if let Some(r) = w
            .strip_prefix("range=")
            .or_else(|| w.strip_prefix("choices="))
        {
            allowed = r.to_string();
        } else if let Some(d) = w.strip_prefix("default=") {
            default = d.to_string();
        } else {
            unit = w.to_string();
        }
    }
    Some([name.into(), value.into(), unit, allowed, default])
}

/// Prints the settings as an aligned table (lines it cannot read as they came).
fn print_table(data: &[String]) {
    let rows: Vec<_> = data.iter().map(|d| (d, columns(d))).collect();
    let mut width = [7, 5, 4, 7, 7];
    for (_, cols) in &rows {
        for (w, c) in width.iter_mut().zip(cols.iter().flatten()) {
            *w = (*w).max(c.len());
        }
    }
    let head = ["setting", "value", "unit", "allowed", "default"];
    let line = |c: &[&str]| {
        let cells: Vec<String> = c
            .iter()
            .zip(width)
            .map(|(s, w)| format!("{s:<w$}"))
            .collect();
        println!("{}", cells.join("  ").trim_end());
    };
    line(&head);
    for (raw, cols) in &rows {
        match cols {
            Some(c) => line(&c.iter().map(String::as_str).collect::<Vec<_>>()),
            None => println!("data: {raw}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_set_then_saved_does_not_say_saved_no() {
        assert_eq!(
            without_saved_no("ok lock_timeout_s=500.0 saved=no"),
            "ok lock_timeout_s=500.0"
        );
    }

    #[test]
    fn config_lines_split_into_columns() {
        assert_eq!(
            columns("lock_timeout_s=600.0 s range=30.0..900.0 default=600.0").unwrap(),
            ["lock_timeout_s", "600.0", "s", "30.0..900.0", "600.0"].map(String::from)
        );
        assert_eq!(
            columns("auto_mode=closed choices=paper|gated|boost|closed default=closed").unwrap(),
            [
                "auto_mode",
                "closed",
                "",
                "paper|gated|boost|closed",
                "closed"
            ]
            .map(String::from)
        );
        assert_eq!(columns("garbage"), None);
    }
}
