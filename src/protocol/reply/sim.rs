//! The simulated builds' `SIM` replies, and what hardware answers to them.

use super::*;

/// `SIM ...` on hardware.
pub const ERR_SIM_UNSUPPORTED: ProtoError = ProtoError {
    code: ErrorCode::Unsupported,
    text: "SIM commands exist only in simulated builds (morph-sim, the emulator)",
};

/// `SIM PANIC` on the host simulator.
pub const ERR_SIM_PANIC_UNSUPPORTED: ProtoError = ProtoError {
    code: ErrorCode::Unsupported,
    text: "SIM PANIC exists only in the emulated image",
};

/// `SIM STALL` on the host simulator.
pub const ERR_SIM_STALL_UNSUPPORTED: ProtoError = ProtoError {
    code: ErrorCode::Unsupported,
    text: "SIM STALL exists only in the emulated image",
};

/// `SIM WAIT` where the clock cannot be skipped (the emulated image runs at firmware time).
pub const ERR_SIM_WAIT_UNSUPPORTED: ProtoError = ProtoError {
    code: ErrorCode::Unsupported,
    text: "SIM WAIT needs a simulator that owns its clock (morph-sim); firmware time cannot be skipped",
};

/// `SIM STATE`: `ok time_s= radius_mm= t_pla_c= t_tca_c=` (the simulated truth).
pub fn sim_state(l: &mut OutLine, time_s: f32, radius_mm: f32, t_pla_c: f32, t_tca_c: f32) {
    ok_with(
        l,
        format_args!(
            "time_s={} radius_mm={} t_pla_c={} t_tca_c={}",
            Fixed(time_s, 1),
            Fixed(radius_mm, 2),
            Fixed(t_pla_c, 2),
            Fixed(t_tca_c, 2)
        ),
    );
}

/// `SIM FAULT`: `ok fault=<kind> target=<sensor>`.
pub fn sim_fault(l: &mut OutLine, kind: SimFault, target: Sensor) {
    let target = match kind {
        SimFault::CutoffStuck => "supply",
        _ => target.as_str(),
    };
    ok_with(l, format_args!("fault={} target={target}", kind.as_str()));
}

/// `SIM SUPPLY`: `ok supply_v=<V>`.
pub fn sim_supply(l: &mut OutLine, supply_v: f32) {
    ok_with(l, format_args!("supply_v={}", Fixed(supply_v, 2)));
}

/// `SIM SUPPLY` refused: `error: out-of-range supply must be 0..<max> V`.
pub fn sim_supply_out_of_range(l: &mut OutLine, max_v: f32) {
    error(
        l,
        ErrorCode::OutOfRange,
        format_args!("supply must be 0..{} V", Fixed(max_v, 0)),
    );
}

/// `SIM AMBIENT`: `ok t_amb_c=<°C>`.
pub fn sim_ambient(l: &mut OutLine, t_amb_c: f32) {
    ok_with(l, format_args!("t_amb_c={}", Fixed(t_amb_c, 2)));
}

/// `SIM AMBIENT` refused: `error: out-of-range ambient must be <lo>..<hi> C`.
pub fn sim_ambient_out_of_range(l: &mut OutLine, lo_c: f32, hi_c: f32) {
    error(
        l,
        ErrorCode::OutOfRange,
        format_args!("ambient must be {}..{} C", Fixed(lo_c, 0), Fixed(hi_c, 0)),
    );
}

/// `SIM MEDIUM`: `ok medium=<water|air>`.
pub fn sim_medium(l: &mut OutLine, m: Medium) {
    ok_with(l, format_args!("medium={}", m.as_str()));
}

/// `SIM WAIT` refused: `error: out-of-range wait must be 0..<max> s`.
pub fn sim_wait_out_of_range(l: &mut OutLine, max_s: f32) {
    error(
        l,
        ErrorCode::OutOfRange,
        format_args!("wait must be 0..{} s", Fixed(max_s, 0)),
    );
}

/// A `SIM` setting the plant refused (`SIM SUPPLY`, `SIM AMBIENT`, `SIM MEDIUM` on a plant
/// that cannot change it): `error: unsupported SIM <WORD>: the plant cannot change that`.
pub fn sim_setting_unsupported(l: &mut OutLine, setting: SimSetting) {
    error(
        l,
        ErrorCode::Unsupported,
        format_args!("SIM {}: the plant cannot change that", setting.as_str()),
    );
}

/// A `SIM` command that changes the plant (for [`sim_setting_unsupported`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SimSetting {
    /// `SIM SUPPLY`.
    Supply,
    /// `SIM AMBIENT`.
    Ambient,
    /// `SIM MEDIUM`.
    Medium,
}

impl SimSetting {
    /// The command's word.
    pub fn as_str(self) -> &'static str {
        match self {
            SimSetting::Supply => "SUPPLY",
            SimSetting::Ambient => "AMBIENT",
            SimSetting::Medium => "MEDIUM",
        }
    }
}

/// `SIM FAULT thermistor-drift`: `ok fault=thermistor-drift target=<sensor> rate_k_per_s=<K/s>`.
pub fn sim_fault_drift(l: &mut OutLine, target: Sensor, rate_k_per_s: f32) {
    ok_with(
        l,
        format_args!(
            "fault={} target={} rate_k_per_s={}",
            SimFault::ThermistorDrift.as_str(),
            target.as_str(),
            Fixed(rate_k_per_s, 3)
        ),
    );
}

/// `SIM FAULT thermistor-drift` refused: `error: out-of-range drift must be -<max>..<max> K/s`.
pub fn sim_drift_out_of_range(l: &mut OutLine, max_k_per_s: f32) {
    error(
        l,
        ErrorCode::OutOfRange,
        format_args!(
            "drift must be -{}..{} K/s",
            Fixed(max_k_per_s, 1),
            Fixed(max_k_per_s, 1)
        ),
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::format_error;
    use crate::protocol::reply::line;

    #[test]
    fn sim_replies() {
        let l = line(|l| sim_state(l, 12.34, 38.456, 70.0, 40.125));
        assert_eq!(
            l,
            "ok time_s=12.3 radius_mm=38.46 t_pla_c=70.00 t_tca_c=40.13"
        );
        let l = line(|l| sim_fault(l, SimFault::HeaterOpen, Sensor::Tca));
        assert_eq!(l, "ok fault=heater-open target=tca");
        assert_eq!(
            line(|l| sim_fault_drift(l, Sensor::Tca, -0.2)),
            "ok fault=thermistor-drift target=tca rate_k_per_s=-0.200"
        );
        assert_eq!(
            line(|l| sim_drift_out_of_range(l, 10.0)),
            "error: out-of-range drift must be -10.0..10.0 K/s"
        );
        assert_eq!(line(|l| sim_supply(l, 5.0)), "ok supply_v=5.00");
        assert_eq!(
            line(|l| sim_supply_out_of_range(l, 30.0)),
            "error: out-of-range supply must be 0..30 V"
        );
        assert_eq!(line(|l| sim_ambient(l, -5.0)), "ok t_amb_c=-5.00");
        assert_eq!(
            line(|l| sim_ambient_out_of_range(l, -10.0, 60.0)),
            "error: out-of-range ambient must be -10..60 C"
        );
        assert_eq!(line(|l| sim_medium(l, Medium::Air)), "ok medium=air");
        assert_eq!(
            line(|l| sim_wait_out_of_range(l, 3600.0)),
            "error: out-of-range wait must be 0..3600 s"
        );
        assert_eq!(
            line(|l| sim_setting_unsupported(l, SimSetting::Medium)),
            "error: unsupported SIM MEDIUM: the plant cannot change that"
        );
        assert_eq!(
            format_error(&ERR_SIM_WAIT_UNSUPPORTED),
            "error: unsupported SIM WAIT needs a simulator that owns its clock (morph-sim); \
             firmware time cannot be skipped"
        );
        assert_eq!(line(ok), "ok");
        assert_eq!(
            format_error(&ERR_SIM_PANIC_UNSUPPORTED),
            "error: unsupported SIM PANIC exists only in the emulated image"
        );
    }
}
