//! Wire text of several links on one board: the link address (`@<n>` before any command, `@*`
//! for every link), `GAIT` (one target a link), `LINKS` (the links and the supply budget),
//! the budget's settings and the events a shared supply adds. docs/protocol.md, "Several
//! links".

use super::reply::{data, error};
use super::{ErrorCode, Mode, OutLine, ProtoError, MODES};
use crate::budget::{BudgetError, MAX_LINKS};
use crate::fixed::Fixed;
use crate::vocab::Phase;
use core::fmt::Write;

/// The doc that explains several links and the supply budget; their errors point to it.
pub const LINKS_DOC: &str = "docs/multilink.md";

/// Which link a line is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Address {
    /// One link, 0-based (`@1` is link 0).
    Link(usize),
    /// Every link (`@*`).
    All,
}

/// The commands of several links (the rest go to one link's controller).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LinksCommand {
    /// `GAIT <r1> ... <rN> [mode]`: a morph on every link at once, one target each, mm.
    Gait {
        /// Target radius of each link, mm (as many as sent).
        radii_mm: [f32; MAX_LINKS],
        /// How many targets were sent.
        count: usize,
        /// The strategy every link runs.
        mode: Mode,
    },
    /// `LINKS`: each link's phase and share, and the supply's total against its budget.
    Links,
}

/// The board's settings of the shared supply (CONFIG SET takes them like a link's).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SupplySetting {
    /// `supply_budget_w`, W.
    BudgetW,
    /// `supply_limit_a`, A.
    LimitA,
}

impl SupplySetting {
    /// Every supply setting.
    pub const ALL: [SupplySetting; 2] = [SupplySetting::BudgetW, SupplySetting::LimitA];

    /// Wire name.
    pub fn as_str(self) -> &'static str {
        match self {
            SupplySetting::BudgetW => "supply_budget_w",
            SupplySetting::LimitA => "supply_limit_a",
        }
    }

    /// Unit as CONFIG shows it.
    pub fn unit(self) -> &'static str {
        match self {
            SupplySetting::BudgetW => "W",
            SupplySetting::LimitA => "A",
        }
    }
}

const fn bad(text: &'static str) -> ProtoError {
    ProtoError {
        code: ErrorCode::BadArgument,
        text,
    }
}

/// Splits a leading address off `line`: `@2 MORPH 38` is link 1's `MORPH 38`, `@* STATUS`
/// every link's `STATUS`; a line without one has `None`. Whether the link exists is the
/// caller's to judge ([`address_past`]).
pub fn split_address(line: &str) -> Result<(Option<Address>, &str), ProtoError> {
    let line = line.trim_start_matches([' ', '\t']);
    let Some(rest) = line.strip_prefix('@') else {
        return Ok((None, line));
    };
    let (word, rest) = rest.split_once([' ', '\t']).unwrap_or((rest, ""));
    const BAD: ProtoError =
        bad("A link address is @<n> (from @1) or @* before a command, e.g. @2 MORPH 38.");
    // Plain decimal digits, no sign and no leading zero, at most three (`@01`, `@+2` and a
    // number past any `usize` are the same mistake on every platform).
    let digits = !word.is_empty()
        && word.len() <= 3
        && word.bytes().all(|b| b.is_ascii_digit())
        && !word.starts_with('0');
    let address = if word == "*" {
        Address::All
    } else if digits {
        Address::Link(word.parse::<usize>().map_err(|_| BAD)? - 1)
    } else {
        return Err(BAD);
    };
    if rest.trim().is_empty() {
        return Err(bad(
            "A link address needs a command after it, e.g. @2 STATUS.",
        ));
    }
    if rest.trim_start().starts_with('@') {
        return Err(bad("One address per line, e.g. @2 STATUS."));
    }
    Ok((Some(address), rest))
}

/// True if `line` starts heating on a board of several links, so that read ahead of an ABORT
/// it is refused: GAIT (every link), and MORPH, TUNE or HEAT addressed to a link or to `@*`
/// as unaddressed.
pub fn starts_heating(line: &str) -> bool {
    match split_address(line) {
        Ok((_, cmd)) => {
            matches!(
                parse_links_command(cmd),
                Some(Ok(LinksCommand::Gait { .. }))
            ) || super::serial::starts_heating(cmd)
        }
        Err(_) => false,
    }
}

/// Parses `line` if it is one of the several-links commands (`GAIT`, `LINKS`); `None` for
/// any other line.
pub fn parse_links_command(line: &str) -> Option<Result<LinksCommand, ProtoError>> {
    let mut words = line.split([' ', '\t']).filter(|w| !w.is_empty());
    let first = words.next()?;
    if first.eq_ignore_ascii_case("LINKS") {
        return Some(match words.next() {
            None => Ok(LinksCommand::Links),
            Some(_) => Err(ProtoError {
                code: ErrorCode::NoArguments,
                text: "LINKS",
            }),
        });
    }
    if !first.eq_ignore_ascii_case("GAIT") {
        return None;
    }
    let mut radii_mm = [0.0; MAX_LINKS];
    let mut count = 0;
    let mut mode = None;
    const FORM: ProtoError =
        bad("GAIT takes one radius in mm per link, then an optional mode, e.g. GAIT 38 40.");
    for w in words {
        // The mode comes last, once: a word after it is a mistake, not a second choice.
        if mode.is_some() {
            return Some(Err(FORM));
        }
        if let Some(m) = MODES.iter().find(|m| m.as_str().eq_ignore_ascii_case(w)) {
            mode = Some(*m);
            continue;
        }
        let Some(r) = crate::fixed::parse_decimal(w).filter(|r| r.is_finite() && *r > 0.0) else {
            return Some(Err(FORM));
        };
        if count == MAX_LINKS {
            return Some(Err(bad("GAIT takes at most one radius per link.")));
        }
        radii_mm[count] = r;
        count += 1;
    }
    if count == 0 {
        return Some(Err(bad(
            "GAIT needs one radius in mm per link, e.g. GAIT 38 40.",
        )));
    }
    Some(Ok(LinksCommand::Gait {
        radii_mm,
        count,
        mode: mode.unwrap_or(Mode::Auto),
    }))
}

/// Whether a board of several links would parse `line` (an address, then a command: GAIT,
/// LINKS or any one link's command); the error it would answer. What a client checks a script
/// against before sending anything. Whether the link exists is the board's to say.
pub fn check_line(line: &str) -> Result<(), ProtoError> {
    let (_, rest) = split_address(line)?;
    match parse_links_command(rest) {
        Some(r) => r.map(|_| ()),
        None => super::parse_line(rest).map(|_| ()),
    }
}

/// Which supply setting `CONFIG SET <name> ...` names, if any.
pub fn supply_setting(name: &str) -> Option<SupplySetting> {
    SupplySetting::ALL
        .into_iter()
        .find(|s| s.as_str().eq_ignore_ascii_case(name))
}

/// HELP's lines of several links (a board with one link does not show them).
pub const HELP_LINKS: [&str; 4] = [
    "@<n> <command>\tthe command for link n (from @1); no address is link 1",
    "@* <command>\tthe command on every link, one data line each; ABORT alone stops every link",
    "GAIT <r1> .. <rN> [mode]\tmorph every link at once, one radius each (mm)",
    "LINKS\teach link's phase and power, the supply's total against its budget",
];

/// A MORPH for a link whose last MORPH still waits for the budget.
pub const ERR_QUEUED: ProtoError = ProtoError {
    code: ErrorCode::Busy,
    text: "this link's last MORPH waits for room in the supply budget; ABORT it first",
};

/// `@* SIM ...`: a simulated link's SIM line names one link.
pub const ERR_SIM_EACH: ProtoError = bad("SIM lines name one link (@<n> SIM ...), not @*.");

/// `SAVE` sent to every link at once: each link's SAVE is a flash write of its own.
pub const ERR_SAVE_EACH: ProtoError = bad("SAVE one link at a time (SAVE is link 1's), not @*.");

/// `SAVE` while any link heats or waits for the budget: a flash write stalls the CPU, and
/// every link's heaters must be off through it.
pub const ERR_SAVE_BUSY: ProtoError = ProtoError {
    code: ErrorCode::Busy,
    text: "SAVE waits until every link is idle (a flash write stalls the CPU); ABORT or wait",
};

/// GAIT, LINKS or a supply setting sent with an address: they are the board's.
pub const ERR_BOARD_ADDRESSED: ProtoError =
    bad("GAIT, LINKS and the supply's settings are the board's: send them without an address.");

/// `<prefix><line>`: a link's line as a board of several links sends it, `@<n> ` first.
pub fn addressed(l: &mut OutLine, link: usize, line: &str) {
    let _ = write!(l, "@{} {line}", link + 1);
}

/// `data: @<n> <line>`: one link's final reply to an `@*` command.
pub fn each_reply(l: &mut OutLine, link: usize, line: &str) {
    data(l, format_args!("@{} {line}", link + 1));
}

/// The end of an `@*` command: `ok links=<n>`.
pub fn each_end(l: &mut OutLine, links: usize) {
    let _ = write!(l, "ok links={links}");
}

/// `error: out-of-range no link <n>; this board has links 1 to <count>`.
pub fn address_past(l: &mut OutLine, link: usize, count: usize) {
    error(
        l,
        ErrorCode::OutOfRange,
        format_args!("no link {}; this board has links 1 to {count}", link + 1),
    );
}

/// A GAIT with the wrong number of targets.
pub fn gait_count(l: &mut OutLine, sent: usize, count: usize) {
    error(
        l,
        ErrorCode::BadArgument,
        format_args!("GAIT took {sent} radii; this board has {count} links, one radius each"),
    );
}

/// A GAIT refused because one link cannot start: `error: <why> link <n>: <its refusal>`
/// (nothing was started).
pub fn gait_refused(l: &mut OutLine, link: usize, refusal: &str) {
    let _ = write!(l, "{refusal} (link {}; no link was started)", link + 1);
}

/// A morph whose soften alone needs more than the whole budget.
pub fn morph_over_budget(l: &mut OutLine, needs_w: f32, budget_w: f32) {
    error(
        l,
        ErrorCode::OutOfRange,
        format_args!(
            "this morph's soften needs {} W of the supply; supply_budget_w is {} W ({LINKS_DOC})",
            Fixed::up2(needs_w),
            Fixed(budget_w, 2)
        ),
    );
}

/// `ok queued needs_w=<w> free_w=<w>`: a MORPH (or a GAIT's) that waits for room in the budget
/// before it softens; it starts by itself.
pub fn queued_event(l: &mut OutLine, needs_w: f32, free_w: f32) {
    let _ = write!(
        l,
        "event: queued needs_w={} free_w={}",
        Fixed(needs_w, 2),
        Fixed(free_w, 2)
    );
}

/// The shared supply sagged to `pulse_v` (V) inside the heaters' pulses while `limit_a` (A) is
/// the limit the scheduler lays them out under: `event: supply sags to <V> V inside the heaters'
/// pulses: its own current limit is under supply_limit_a=<A>; set supply_limit_a to it
/// (docs/multilink.md)`. Every link then stops with `supply-out-of-range`.
pub fn supply_sag_event(l: &mut OutLine, pulse_v: f32, limit_a: f32) {
    let _ = write!(
        l,
        "event: supply sags to {} V inside the heaters' pulses: its own current limit is under supply_limit_a={}; set supply_limit_a to it ({LINKS_DOC})",
        Fixed(pulse_v, 1),
        Fixed(limit_a, 2)
    );
}

/// A queued morph that could not start once the budget had room (a fault latched meanwhile):
/// `event: queued-morph dropped (<its refusal>)`.
pub fn queued_dropped_event(l: &mut OutLine, refusal: &str) {
    let _ = write!(l, "event: queued-morph dropped ({refusal})");
}

/// Why the supply's settings boot as the defaults.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SupplyDefaults {
    /// No SAVE kept them.
    Absent,
    /// Kept in a form this firmware does not read.
    Format,
    /// Kept, but outside what `CONFIG SET` would take now.
    OutOfRange,
    /// The flash could not be read.
    Flash,
}

/// The supply's settings a SAVE kept, in force from boot:
/// `event: config supply loaded supply_budget_w=<W> supply_limit_a=<A>`.
pub fn supply_loaded_event(l: &mut OutLine, budget_w: f32, limit_a: f32) {
    let _ = write!(
        l,
        "event: config supply loaded supply_budget_w={} supply_limit_a={}",
        Fixed(budget_w, 2),
        Fixed(limit_a, 2)
    );
}

/// The supply's settings boot as their defaults: `event: config supply defaults reason=<why>`.
pub fn supply_defaults_event(l: &mut OutLine, why: SupplyDefaults) {
    let why = match why {
        SupplyDefaults::Absent => "absent",
        SupplyDefaults::Format => "format",
        SupplyDefaults::OutOfRange => "out-of-range",
        SupplyDefaults::Flash => "flash-error",
    };
    let _ = write!(l, "event: config supply defaults reason={why}");
}

/// `CONFIG SET` of a supply setting done: `ok <name>=<value> saved=no`.
pub fn supply_set(l: &mut OutLine, s: SupplySetting, value: f32) {
    let _ = write!(l, "ok {}={} saved=no", s.as_str(), Fixed(value, 2));
}

/// A supply setting refused (nothing changed).
pub fn supply_refused(l: &mut OutLine, s: SupplySetting, value: f32, why: BudgetError) {
    let (name, unit) = (s.as_str(), s.unit());
    match why {
        BudgetError::OutOfRange { min, max } => error(
            l,
            ErrorCode::OutOfRange,
            format_args!(
                "{name} takes {}..{} {unit} ({LINKS_DOC})",
                Fixed::up2(min),
                Fixed::down2(max)
            ),
        ),
        BudgetError::TooSmall { least } => error(
            l,
            ErrorCode::OutOfRange,
            format_args!(
                "{name} {} {unit} is too small: the least that works is {} {unit} ({LINKS_DOC})",
                Fixed(value, 2),
                Fixed::up2(least)
            ),
        ),
    }
}

/// A budget raised past what the supply gives at its current limit and measured voltage.
pub fn budget_over_supply(l: &mut OutLine, value: f32, most_w: f32) {
    error(
        l,
        ErrorCode::OutOfRange,
        format_args!(
            "supply_budget_w {} W is more than the supply gives, {} W at supply_limit_a and the \
             measured supply ({LINKS_DOC})",
            Fixed(value, 2),
            Fixed::down2(most_w)
        ),
    );
}

/// A budget lowered under what the running links hold.
pub fn budget_under_reserves(l: &mut OutLine, value: f32, held_w: f32) {
    error(
        l,
        ErrorCode::Busy,
        format_args!(
            "supply_budget_w {} W is less than the running morphs hold, {} W; lower it once \
             they are done ({LINKS_DOC})",
            Fixed(value, 2),
            Fixed(held_w, 2)
        ),
    );
}

/// A budget lowered under what a queued morph needs to start (`link`, 0-based).
pub fn budget_under_queued(l: &mut OutLine, value: f32, needs_w: f32, link: usize) {
    error(
        l,
        ErrorCode::Busy,
        format_args!(
            "supply_budget_w {} W is less than the morph queued on link {} needs, {} W; ABORT it \
             first ({LINKS_DOC})",
            Fixed(value, 2),
            link + 1,
            Fixed::up2(needs_w)
        ),
    );
}

/// A current limit lowered under what the budget draws at the measured supply.
pub fn limit_under_budget(l: &mut OutLine, value: f32, most_w: f32, budget_w: f32) {
    error(
        l,
        ErrorCode::OutOfRange,
        format_args!(
            "supply_limit_a {} A gives {} W at the measured supply, under supply_budget_w {} W; \
             lower supply_budget_w first ({LINKS_DOC})",
            Fixed(value, 2),
            Fixed::down2(most_w),
            Fixed(budget_w, 2)
        ),
    );
}

/// A TUNE or HEAT (`what`) whose fixed powers, `needs_w`, do not fit beside the running and
/// queued morphs: it would take their reserves.
pub fn fixed_over_budget(l: &mut OutLine, what: &str, needs_w: f32, free_w: f32) {
    error(
        l,
        ErrorCode::Busy,
        format_args!(
            "{what} holds {} W of the supply; supply_budget_w has {} W free beside the running \
             and queued morphs: send it when they are done ({LINKS_DOC})",
            Fixed::up2(needs_w),
            Fixed::down2(free_w.max(0.0))
        ),
    );
}

/// Why a queued morph is dropped when the links ahead of it are done and it still cannot
/// start: `error: out-of-range the supply cannot start this morph with every link idle: its
/// soften needs <W> W under supply_budget_w=<W> and supply_limit_a=<A>`.
pub fn never_starts(l: &mut OutLine, needs_w: f32, budget_w: f32, limit_a: f32) {
    error(
        l,
        ErrorCode::OutOfRange,
        format_args!(
            "the supply cannot start this morph with every link idle: its soften needs {} W \
             under supply_budget_w={} and supply_limit_a={} ({LINKS_DOC})",
            Fixed::up2(needs_w),
            Fixed(budget_w, 2),
            Fixed(limit_a, 2)
        ),
    );
}

/// One link's `LINKS` line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinkRow {
    /// The link, 0-based.
    pub link: usize,
    /// Its phase.
    pub phase: Phase,
    /// A morph waits for the budget.
    pub queued: bool,
    /// Its heaters' powers last tick, W (PLA + TCA).
    pub power_w: f32,
    /// Its allowance this tick, W (PLA + TCA).
    pub allow_w: f32,
    /// What holds what it runs, W.
    pub reserve_w: f32,
}

/// `data: @<n> phase=<p> queued=<yes|no> power_w=<w> allow_w=<w> reserve_w=<w>`.
pub fn links_row(l: &mut OutLine, r: &LinkRow) {
    data(
        l,
        format_args!(
            "@{} phase={} queued={} power_w={} allow_w={} reserve_w={}",
            r.link + 1,
            r.phase.as_str(),
            if r.queued { "yes" } else { "no" },
            Fixed(r.power_w, 3),
            Fixed(r.allow_w, 3),
            Fixed(r.reserve_w, 3)
        ),
    );
}

/// `ok links=<n> power_w=<w> budget_w=<w> limit_a=<a> supply_v=<v>`.
pub fn links_end(
    l: &mut OutLine,
    links: usize,
    power_w: f32,
    budget_w: f32,
    limit_a: f32,
    supply_v: f32,
) {
    let _ = write!(
        l,
        "ok links={links} power_w={} budget_w={} limit_a={} supply_v={}",
        Fixed(power_w, 3),
        Fixed(budget_w, 2),
        Fixed(limit_a, 2),
        Fixed(supply_v, 2)
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_address_is_split_off_and_bad_ones_are_named() {
        assert_eq!(split_address("MORPH 38").unwrap(), (None, "MORPH 38"));
        assert_eq!(
            split_address("@2 MORPH 38").unwrap(),
            (Some(Address::Link(1)), "MORPH 38")
        );
        assert_eq!(
            split_address("@* STATUS").unwrap(),
            (Some(Address::All), "STATUS")
        );
        for bad in ["@0 STATUS", "@x STATUS", "@2", "@ STATUS", "@-1 STATUS"] {
            assert!(split_address(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn gait_takes_radii_and_a_mode() {
        let Some(Ok(LinksCommand::Gait {
            radii_mm,
            count,
            mode,
        })) = parse_links_command("GAIT 38 40.5 closed")
        else {
            panic!()
        };
        assert_eq!((count, mode), (2, Mode::Closed));
        assert_eq!(&radii_mm[..2], &[38.0, 40.5]);
        for bad in ["GAIT", "GAIT 38 x", "GAIT 0", "GAIT 1 2 3 4 5", "GAIT nan"] {
            assert!(matches!(parse_links_command(bad), Some(Err(_))), "{bad}");
        }
        assert_eq!(parse_links_command("MORPH 38"), None);
        assert_eq!(parse_links_command("LINKS"), Some(Ok(LinksCommand::Links)));
    }
}
