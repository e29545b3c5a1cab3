//! The type file's own checks: the built-in 160EC against the paper's tables, and every
//! refusal of a malformed file.

use super::*;

#[test]
fn builtin_data_is_valid_and_traceable_to_table_4() {
    let t = PantographType::from_toml(PANTOGRAPH_160EC_TOML).unwrap();
    // Table 4, spot checks against the paper's printed values.
    let j1 = t.joint("J1").unwrap();
    assert_eq!(
        (j1.viscous_baseline(), j1.dry_mu, j1.pin_radius_m),
        (0.034, 0.023, Some(0.05))
    );
    let j5 = t.joint("J5").unwrap();
    assert_eq!(
        (j5.viscous_baseline(), j5.dry_mu, j5.pin_radius_m),
        (0.401, 0.88, Some(0.01))
    );
    assert_eq!(
        t.joint("J2'").unwrap().dry_mu,
        t.joint("J2").unwrap().dry_mu
    );
    // Table 2.
    assert_eq!(t.bodies["upper_arm"].inertia_axis_kgm2, Some(5.98));
    for name in ["J1", "J2", "J2'", "J3", "J4", "J5", "J6", "J7"] {
        assert!(t.rigs.contains_key(name), "rig for {name}");
        assert!(
            t.joints[name].source.contains("Table 4"),
            "{name} cites Table 4"
        );
    }
}

/// Issue 18: a record's clock is held to `[rig_limits]` — a time far from the test's zero
/// (`t_s = [0, 1e300]`), an interval outside the sampling span, a record over the longest
/// duration are refused naming `channels.t_s[i]` or `channels.t_s`; the spans' ends pass.
#[test]
fn sampling_outside_the_rig_limits_is_refused_naming_t_s() {
    let l = builtin_160ec().rig_limits();
    let [dt_lo, dt_hi] = l.sample_interval_s;
    let field = |t: &[f64]| l.check_sampling(t).map_err(|(f, _)| f);
    assert_eq!(field(&[0.0, 1e300, 2e300]), Err("channels.t_s[1]".into()));
    assert_eq!(
        field(&[l.time_s[0] - 1.0, 0.0]),
        Err("channels.t_s[0]".into())
    );
    assert_eq!(
        field(&[0.0, 0.002, 0.002 + dt_hi * 2.0]),
        Err("channels.t_s[2]".into())
    );
    assert_eq!(field(&[0.0, dt_lo / 2.0]), Err("channels.t_s[1]".into()));
    let long: Vec<f64> = (0..=(l.record_duration_max_s / dt_hi) as usize + 1)
        .map(|i| i as f64 * dt_hi)
        .collect();
    assert_eq!(field(&long), Err("channels.t_s".into()));
    assert_eq!(
        field(&long[..long.len() - 1]),
        Ok(()),
        "exactly the longest record"
    );
    assert_eq!(field(&[-dt_hi, 0.0, dt_lo]), Ok(()));
    assert_eq!(field(&[l.time_s[1] - 1.0, l.time_s[1]]), Ok(()));
}

/// docs/API.md "Input limits" is these values: a row per `[rig_limits]` key with its span.
#[test]
fn the_api_doc_lists_every_rig_limit() {
    let doc = include_str!("../../../docs/API.md");
    let l = builtin_160ec().rig_limits();
    let spans = [
        ("pin_radius_m", l.pin_radius_m),
        ("mass_kg", l.mass_kg),
        ("inertia_kgm2", l.inertia_kgm2),
        ("com_distance_m", l.com_distance_m),
        ("attachment_m", l.attachment_m),
        ("gravity_m_s2", l.gravity_m_s2),
        ("initial_rate_deg_s", l.initial_rate_deg_s),
        ("moving_mass_kg", l.moving_mass_kg),
        ("springs", l.springs),
        ("spring_stiffness_n_per_mm", l.spring_stiffness_n_per_mm),
        ("normal_force_n", l.normal_force_n),
        ("incline_deg", l.incline_deg),
        ("lift_strip_height_m", l.lift_strip_height_m),
        ("lift_strip_force_n", l.lift_strip_force_n),
        ("sample_interval_s", l.sample_interval_s),
        ("time_s", l.time_s),
    ];
    let mut rows: Vec<String> = spans
        .iter()
        .map(|(k, [lo, hi])| format!("| `{k}` | [{lo}, {hi}] |"))
        .collect();
    for (k, v) in [
        ("alpha_deg_abs", l.alpha_deg_abs),
        ("h_mm_abs", l.h_mm_abs),
        ("force_n_abs", l.force_n_abs),
        ("record_duration_max_s", l.record_duration_max_s),
    ] {
        rows.push(format!("| `{k}` | {v} |"));
    }
    if let Some([lo, hi]) = crate::lift::geometry::builtin_160ec().drive_torque_range_nm {
        rows.push(format!(
            "| `[drive] torque_range_Nm` (geometry file) | [{lo}, {hi}] |"
        ));
    }
    let missing: Vec<&String> = rows.iter().filter(|r| !doc.contains(*r)).collect();
    assert!(
        missing.is_empty(),
        "docs/API.md \"Input limits\" lacks {missing:#?}"
    );
}

#[test]
fn invalid_data_names_the_field() {
    let bad = PANTOGRAPH_160EC_TOML.replace("dry_mu = 0.88", "dry_mu = -0.88");
    let err = PantographType::from_toml(&bad).unwrap_err().to_string();
    assert!(err.contains("joints.J5.dry_mu"), "{err}");
    let bad = PANTOGRAPH_160EC_TOML.replace("body = \"upper_arm\"", "body = \"nope\"");
    let err = PantographType::from_toml(&bad).unwrap_err().to_string();
    assert!(err.contains("rigs.J3.body"), "{err}");
    let bad = PANTOGRAPH_160EC_TOML.replace("inertia_axis_kgm2 = 5.61", "inertia_axis_kgm2 = 0.5");
    let err = PantographType::from_toml(&bad).unwrap_err().to_string();
    assert!(err.contains("parallel-axis"), "{err}");
}
