//! The recorded channels of a lift trace, as the fit reads them, and the stand's limits they
//! must keep (issue 18).

/// The recorded channels of a lift trace (contract `lift` kind).
#[derive(Debug, Clone, Copy)]
pub struct LiftChannels<'a> {
    pub t_s: &'a [f64],
    pub strip_height_m: &'a [f64],
    pub torque_nm: &'a [f64],
    pub fs_n: &'a [f64],
    /// Empty when the trace has no `Fm_N` (zero).
    pub fm_n: &'a [f64],
}

impl<'a> From<&'a crate::lift::protocol::LiftRecord> for LiftChannels<'a> {
    /// A simulated record's channels, as a trace of it would carry them.
    fn from(r: &'a crate::lift::protocol::LiftRecord) -> Self {
        Self {
            t_s: &r.t_s,
            strip_height_m: &r.strip_height_m,
            torque_nm: &r.torque_nm,
            fs_n: &r.fs_n,
            fm_n: &r.fm_n,
        }
    }
}

impl LiftChannels<'_> {
    /// Every channel within what this stand can record (issue 18), the first sample outside
    /// named (`channels.H_m[3]`): `T_Nm` within the drive's range
    /// (`models/data/160ec-geometry.toml`, `[drive] torque_range_Nm`, when the geometry states
    /// one); `H_m` within the type's working heights and `Fs_N`, `Fm_N` within the strip loads
    /// the drive can hold (`models/data/160ec.toml`, `[rig_limits] lift_strip_height_m`,
    /// `lift_strip_force_n`). `Err((field, message))`.
    pub fn check_limits(&self) -> Result<(), (String, String)> {
        if let Some([lo, hi]) = crate::lift::geometry::builtin_160ec().drive_torque_range_nm
            && let Some(i) = self.torque_nm.iter().position(|t| !(lo..=hi).contains(t))
        {
            return Err((
                format!("channels.T_Nm[{i}]"),
                format!(
                    "{} N·m is outside the drive's range [{lo}, {hi}] N·m (models/data/160ec-geometry.toml, `[drive] torque_range_Nm`)",
                    self.torque_nm[i]
                ),
            ));
        }
        let l = crate::data::builtin_160ec().rig_limits();
        use crate::data::RigLimits;
        RigLimits::check_channel_span("H_m", self.strip_height_m, l.lift_strip_height_m, "m")?;
        RigLimits::check_channel_span("Fs_N", self.fs_n, l.lift_strip_force_n, "N")?;
        RigLimits::check_channel_span("Fm_N", self.fm_n, l.lift_strip_force_n, "N")
    }
}
