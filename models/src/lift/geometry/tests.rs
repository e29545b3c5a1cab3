use super::*;

#[test]
fn builtin_geometry_is_valid_and_traceable() {
    let g = Geometry::from_toml(GEOMETRY_160EC_TOML).unwrap();
    assert_eq!(g.model, "160EC");
    // Table 4 spot checks, through the file.
    let j3 = &g.revolute[RevJoint::J3.index()];
    assert_eq!(
        (j3.viscous_nms_per_rad, j3.dry_mu, j3.pin_radius_m),
        (0.017, 0.20, 0.022)
    );
    assert!(j3.source.contains("Table 4"));
    assert!(g.revolute[RevJoint::J6.index()].locked);
    assert_eq!(
        g.slide.j8_count * g.slide.j8_normal_force_n_each * g.slide.j8_dry_mu,
        8.1
    );
    // Table 2 through the file.
    assert_eq!(g.body(BodyId::UpperArm).mass_kg, 10.1);
    assert!(g.body(BodyId::LowerArm).source.contains("Table 2"));
    assert_eq!(g.reference_poses.len(), 4);
    assert_eq!(g.checks.t_eq_initial_nm, Some(1110.0));
    assert_eq!(g.lift_test.initial.strip_load_n(), 96.5);
}

#[test]
fn invalid_geometry_names_the_key() {
    let cases = [
        ("dry_mu = 0.88", "dry_mu = -0.88", "joints.J5.dry_mu"),
        (
            "mass_kg = 10.1 ",
            "mass_kg = 0.0 ",
            "bodies.upper_arm.mass_kg",
        ),
        (
            "J5 = [1.8500, 0.0000]\n",
            "J9 = [1.8500, 0.0000]\n",
            "bodies.upper_arm.points_m.J5",
        ),
        (
            "bodies = [\"lower_arm\", \"upper_arm\"]",
            "bodies = [\"upper_arm\", \"lower_arm\"]",
            "joints.J3.bodies",
        ),
        (
            "lower_loop_sign = 1",
            "lower_loop_sign = 0",
            "assembly.lower_loop_sign",
        ),
        (
            "planar_rotation = \"locked\"",
            "planar_rotation = \"free\"",
            "joints.J6.planar_rotation",
        ),
        (
            "inertia_axis_kgm2 = 5.61 ",
            "inertia_axis_kgm2 = 6.61 ",
            "bodies.lower_arm.inertia_axis_kgm2",
        ),
        (
            "j8_dry_force_total_N = 8.1 ",
            "j8_dry_force_total_N = 9.1 ",
            "head_suspension.j8_dry_force_total_N",
        ),
        (
            "format = \"160ec-geometry/1\"",
            "format = \"160ec-geometry/9\"",
            "meta.format",
        ),
    ];
    for (from, to, key) in cases {
        assert!(GEOMETRY_160EC_TOML.contains(from), "fixture `{from}`");
        let err = Geometry::from_toml(&GEOMETRY_160EC_TOML.replacen(from, to, 1))
            .unwrap_err()
            .to_string();
        assert!(err.contains(&format!("`{key}`")), "{key}: {err}");
    }
    let err = Geometry::from_toml("meta = 3").unwrap_err();
    assert!(matches!(err, GeometryError::Parse(_)));
}
