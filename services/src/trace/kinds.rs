//! Each test kind's view of a parsed document: a lift's channels and protocol, a quadrangle
//! swing's, a force gauge's readings, a single joint's test and baseline.

use super::wire::{
    self, Finite, PendulumAttachment, PendulumRig, QuadrangleRig, SliderRig, WireBody, WireTest,
};
use super::*;
use pantowatch_models::lift::protocol::LiftProtocol;

/// A value the rules require: `field` "is required" when it is missing.
fn req(v: Option<Finite>, field: &str) -> Result<f64, TraceError> {
    v.map(|Finite(x)| x)
        .ok_or_else(|| bad(field, "is required"))
}

/// An optional number's value.
fn num(v: Option<Finite>) -> Option<f64> {
    v.map(|Finite(x)| x)
}

impl TraceDoc {
    /// The channels of a `lift` test for the complete-pantograph model (built-in 160EC
    /// geometry, `../shared/reference/160ec.toml`).
    ///
    /// The contract allows `test.rig` overrides of that geometry; none is supported yet, so a
    /// non-empty `test.rig` is refused rather than silently ignored.
    fn check_lift(&self, test: &WireTest) -> Result<Option<LiftProtocol>, TraceError> {
        self.geometry_160ec_only("lift tests")?;
        self.whole_pantograph(
            test,
            "a lift test",
            "overrides of the 160EC lift geometry are not supported yet (send an empty rig)",
        )?;
        let get = |name: &str| self.channel(name).unwrap_or_default();
        lift_gaps(get("t_s"))?;
        lift_duration(get("t_s"))?;
        let protocol = Self::lift_protocol(test)?;
        // T within the drive's range, H within the working heights, Fs and Fm within the
        // strip loads the drive can hold (models' data files).
        self.lift_view()
            .check_limits()
            .map_err(|(field, message)| bad(field, message))?;
        Ok(protocol)
    }

    fn lift_view(&self) -> LiftChannels<'_> {
        let get = |name: &str| self.channel(name).unwrap_or_default();
        LiftChannels {
            t_s: get("t_s"),
            strip_height_m: get("H_m"),
            torque_nm: get("T_Nm"),
            fs_n: get("Fs_N"),
            fm_n: get("Fm_N"),
        }
    }

    /// The channels of a `lift` test, checked when the document was parsed ([`TestSpec::Lift`]).
    pub fn lift_channels(&self) -> Result<LiftChannels<'_>, TraceError> {
        match self.spec {
            TestSpec::Lift { .. } => Ok(self.lift_view()),
            _ => Err(bad("test.kind", "not a lift test")),
        }
    }

    /// The drive protocol a lift states it ran (`test.protocol`, optional: as `pantowatch
    /// design-test` writes it), checked against the stand's limits
    /// (`lift::design::ProtocolLimits::stand`, issue 15 point 7): a field outside them is
    /// refused naming it. `None`: not stated.
    ///
    /// A protocol that does not read as one (a key no protocol has, a value of the wrong
    /// shape) is refused naming `test.protocol`, the path inside it in the message.
    fn lift_protocol(test: &WireTest) -> Result<Option<LiftProtocol>, TraceError> {
        use pantowatch_models::lift::design::ProtocolLimits;
        let Some(v) = &test.protocol else {
            return Ok(None);
        };
        let p: LiftProtocol = wire::read(v, "test.protocol")
            .map_err(|e| bad("test.protocol", format!("`{}`: {}", e.field, e.message)))?;
        let lim = ProtocolLimits::stand(pantowatch_models::lift::geometry::builtin_160ec());
        lim.check(&p)
            .map_err(|e| bad(format!("test.protocol.{}", e.field), e.message))?;
        Ok(Some(p))
    }

    /// The channels and stand of a `quadrangle_swing` test for the lower-quadrangle model
    /// (built-in 160EC geometry). `test.rig`: `incline_deg` (default 70), `gravity_m_s2`
    /// (default 9.81), `attachments` (point masses fixed to a body, at body coordinates).
    fn check_quadrangle(&self, test: &WireTest) -> Result<QuadRig, TraceError> {
        self.geometry_160ec_only("quadrangle swings")?;
        if let Some(j) = &self.joint {
            return Err(bad(
                "test.joint",
                format!(
                    "a quadrangle swing is of joints J1, J2, J2', J3 together, got joint `{j}`"
                ),
            ));
        }
        let rig: QuadrangleRig = match &test.rig {
            Some(m) => wire::read_map(m, "test.rig")?,
            None => QuadrangleRig::default(),
        };
        let mut q = QuadRig::default();
        if let Some(v) = num(rig.incline_deg) {
            q.incline_deg = v;
        }
        if let Some(v) = num(rig.gravity_m_s2) {
            q.gravity_m_s2 = v;
        }
        let attachments = rig.attachments.unwrap_or_default();
        if attachments.len() > 16 {
            return Err(bad("test.rig.attachments", "more than 16 attachments"));
        }
        for (i, wire::Obj(a)) in attachments.into_iter().enumerate() {
            let f = format!("test.rig.attachments[{i}]");
            if a.kind.is_none() {
                return Err(bad(format!("{f}.kind"), "must be `point`"));
            }
            let mass_kg = req(a.mass_kg, &format!("{f}.mass_kg"))?;
            let body = a.body.as_deref().and_then(QBody::named).ok_or_else(|| {
                bad(
                    format!("{f}.body"),
                    "must be `lower_arm`, `coupling_rod` or `upper_arm`",
                )
            })?;
            let wire::Pair([x, y]) = a
                .position_m
                .ok_or_else(|| bad(format!("{f}.position_m"), "must be two numbers [x, y], m"))?;
            q.attachments.push(PointMass {
                body,
                mass_kg,
                position_m: V2::from_array([x, y]),
            });
        }
        q.model().map_err(|e| bad(e.field, e.message))?;
        self.quadrangle_view()
            .check_limits()
            .map_err(|e| bad(e.field, e.message))?;
        Ok(q)
    }

    fn quadrangle_view(&self) -> QuadChannels<'_> {
        let get = |name: &str| self.channel(name).unwrap_or_default();
        QuadChannels {
            t_s: get("t_s"),
            alpha_deg: get("alpha_deg"),
            beta_deg: get("beta_deg"),
        }
    }

    /// The channels and stand of a `quadrangle_swing` test, checked when the document was
    /// parsed ([`TestSpec::Quadrangle`]).
    pub fn quadrangle_channels(&self) -> Result<(QuadChannels<'_>, QuadRig), TraceError> {
        match &self.spec {
            TestSpec::Quadrangle(rig) => Ok((self.quadrangle_view(), (**rig).clone())),
            _ => Err(bad("test.kind", "not a quadrangle_swing test")),
        }
    }

    /// The readings of a `static_force` test (a force gauge on the strip, issue 20), checked
    /// by the models' record (`lift::gauge::GaugeRecord`) against the type's `[static_force]`
    /// data: `test.gauge_resolution_n` stated and within `gauge_resolution_range_n`, every `H_m`
    /// within `working_height_m`, every `F_N` within `[rig_limits] lift_strip_force_n`, a raising
    /// branch (H never decreasing up to the first highest reading) then a lowering branch (H
    /// never increasing after it), each of at least `min_points_per_branch` readings.
    fn check_static_force(&self, test: &WireTest) -> Result<(f64, usize), TraceError> {
        let sf = self
            .pantograph_data()
            .and_then(|d| d.static_force.as_ref())
            .filter(|_| self.pantograph_model == "160EC")
            .ok_or_else(|| {
                bad(
                    "pantograph.model",
                    format!(
                        "static_force tests are fitted with the 160EC geometry and its \
                         [static_force] data only, got `{}`",
                        self.pantograph_model
                    ),
                )
            })?;
        self.whole_pantograph(
            test,
            "a static_force test",
            "a static_force test has no rig to state (send an empty rig or none)",
        )?;
        if test.protocol.as_ref().is_some_and(|v| !v.is_null()) {
            return Err(bad(
                "test.protocol",
                "only a lift test states a drive protocol",
            ));
        }
        const RES: &str = "test.gauge_resolution_n";
        let gauge_resolution_n = match test.gauge_resolution_n.flatten().map(|Finite(r)| r) {
            None => {
                return Err(bad(
                    RES,
                    "is required for a static_force test: the gauge's stated resolution, N",
                ));
            }
            Some(r) if r <= 0.0 => return Err(bad(RES, format!("{r} N: must be > 0"))),
            Some(r) => r,
        };
        let get = |name: &str| self.channel(name).unwrap_or_default();
        let (t_s, h, f) = (get("t_s"), get("H_m"), get("F_N"));
        // The record's rules are the models' (`lift::gauge::GaugeRecord`, the type's
        // `[static_force]`): the resolution's span, every height within the working range, both
        // branches, each never turning back and of `min_points_per_branch` readings, every
        // force within the strip loads a drive can hold. One rule set for upload and fit.
        let record = GaugeRecord::with_limits(h.to_vec(), f.to_vec(), gauge_resolution_n, sf)
            .map_err(|e| {
                let field = e.field_path().unwrap_or_else(|| "channels".to_owned());
                let text = e.to_string();
                let message = text
                    .strip_prefix(&format!("{field}: "))
                    .unwrap_or(&text)
                    .to_owned();
                bad(field, message)
            })?;
        let _ = t_s;
        Ok((gauge_resolution_n, record.turn + 1))
    }

    /// The readings of a `static_force` test, checked when the document was parsed
    /// ([`TestSpec::StaticForce`]).
    pub fn static_force_channels(&self) -> Result<GaugeChannels<'_>, TraceError> {
        let TestSpec::StaticForce {
            gauge_resolution_n,
            raise_len,
        } = self.spec
        else {
            return Err(bad("test.kind", "not a static_force test"));
        };
        let get = |name: &str| self.channel(name).unwrap_or_default();
        Ok(GaugeChannels {
            t_s: get("t_s"),
            strip_height_m: get("H_m"),
            force_n: get("F_N"),
            gauge_resolution_n,
            raise_len,
        })
    }

    /// The whole-pantograph kinds (lift, quadrangle swing) are fitted with the built-in 160EC
    /// geometry only.
    fn geometry_160ec_only(&self, what: &str) -> Result<(), TraceError> {
        if self.pantograph_model == "160EC" {
            Ok(())
        } else {
            Err(bad(
                "pantograph.model",
                format!(
                    "{what} are fitted with the 160EC geometry only, got `{}`",
                    self.pantograph_model
                ),
            ))
        }
    }

    /// A test of the whole pantograph (`what`: "a lift test") names no joint and states no
    /// rig: the first rig key is refused with `rig_message`.
    fn whole_pantograph(
        &self,
        test: &WireTest,
        what: &str,
        rig_message: &str,
    ) -> Result<(), TraceError> {
        if let Some(j) = &self.joint {
            return Err(bad(
                "test.joint",
                format!("{what} is of the whole pantograph, got joint `{j}`"),
            ));
        }
        if let Some(k) = test.rig.as_ref().and_then(|r| r.keys().next()) {
            return Err(bad(format!("test.rig.{k}"), rig_message));
        }
        Ok(())
    }

    /// The pantograph type's data when compiled in (`160EC`); `None` for other models.
    pub fn pantograph_data(&self) -> Option<&'static PantographType> {
        data::builtin(&self.pantograph_model)
    }

    /// `test.release_t_s` (issue 17, point 2): when the body was let go, s, on the trace's
    /// clock; only a pendulum states it. It must lie within `t` and leave at least 20 samples of
    /// free motion (what a fit needs).
    fn release_t_s(test: &WireTest, t: &[f64]) -> Result<Option<f64>, TraceError> {
        const FIELD: &str = "test.release_t_s";
        let Some(r) = num(test.release_t_s) else {
            return Ok(None);
        };
        match pantowatch_models::identify::release::stated_release(t, r, 20) {
            Some(_) => Ok(Some(r)),
            None => Err(bad(
                FIELD,
                format!(
                    "{r} s lies outside the trace ({} to {} s) or leaves fewer than 20 samples \
                     after it",
                    t.first().copied().unwrap_or(f64::NAN),
                    t.last().copied().unwrap_or(f64::NAN)
                ),
            )),
        }
    }

    /// The models' single-joint test (pendulum or slider) with its Table 4 baseline, built once
    /// when the document was parsed ([`TestSpec::Joint`]).
    pub fn joint_test(&self) -> Result<(JointTest, Baseline), TraceError> {
        match &self.spec {
            TestSpec::Joint(j) => Ok((j.0.clone(), j.1.clone())),
            _ => Err(bad("test.kind", "not a pendulum or slider test")),
        }
    }

    /// The typed test of the document's kind: every check of the test and its channels that
    /// the models' inputs need, run once, where the document is parsed.
    pub(super) fn typed_spec(&self) -> Result<TestSpec, TraceError> {
        let test: WireTest = wire::read(&self.test, "test")?;
        Ok(match self.kind {
            Kind::Lift => TestSpec::Lift {
                protocol: self.check_lift(&test)?,
            },
            Kind::QuadrangleSwing => TestSpec::Quadrangle(Box::new(self.check_quadrangle(&test)?)),
            Kind::StaticForce => {
                let (gauge_resolution_n, raise_len) = self.check_static_force(&test)?;
                TestSpec::StaticForce {
                    gauge_resolution_n,
                    raise_len,
                }
            }
            Kind::Pendulum | Kind::Slider => {
                TestSpec::Joint(Box::new(self.build_joint_test(&test)?))
            }
        })
    }

    fn build_joint_test(&self, test: &WireTest) -> Result<(JointTest, Baseline), TraceError> {
        let t = self.channel("t_s").unwrap_or_default().to_vec();
        let data = self.pantograph_data();
        let rig_err = |e: pantowatch_models::rig::RigError| bad(e.field, e.message);
        match self.kind {
            Kind::Pendulum => {
                let joint = self
                    .joint
                    .clone()
                    .ok_or_else(|| bad("test.joint", "is required for a pendulum test"))?;
                const JOINTS: [&str; 9] =
                    ["J1", "J2", "J2'", "J3", "J4", "J5", "J6", "J7", "custom"];
                if !JOINTS.contains(&joint.as_str()) {
                    return Err(bad(
                        "test.joint",
                        format!("unknown joint `{joint}` (J1 J2 J2' J3 J4 J5 J6 J7 custom)"),
                    ));
                }
                let rig: PendulumRig = match &test.rig {
                    Some(m) => wire::read_map(m, "test.rig")?,
                    None => PendulumRig::default(),
                };
                // Issue 17, point 1: the body's stated 1 σ errors, each optional; numbers
                // here, their range against the value each qualifies is the models' rule
                // (`rig::check_uncertainty`, once, with the rig).
                let body_uncertainty = rig.body_uncertainty.map(|u| BodyUncertainty {
                    mass_sd_kg: num(u.mass_kg),
                    inertia_sd_kgm2: num(u.inertia_kgm2),
                    com_distance_sd_m: num(u.com_distance_m),
                });
                let body = rig
                    .body
                    .map(|b: WireBody| {
                        const F: &str = "test.rig.body";
                        Ok::<_, TraceError>(BodySpec {
                            mass_kg: req(b.mass_kg, &format!("{F}.mass_kg"))?,
                            inertia_kgm2: req(b.inertia_kgm2, &format!("{F}.inertia_kgm2"))?,
                            com_distance_m: req(b.com_distance_m, &format!("{F}.com_distance_m"))?,
                        })
                    })
                    .transpose()?;
                let attachments = rig
                    .attachments
                    .map(|list| {
                        list.iter()
                            .enumerate()
                            .map(|(i, m)| {
                                let f = format!("test.rig.attachments[{i}]");
                                Ok(match PendulumAttachment::read(m, &f)? {
                                    PendulumAttachment::Point(p) => Attachment::Point {
                                        mass_kg: req(p.mass_kg, &format!("{f}.mass_kg"))?,
                                        distance_m: req(p.distance_m, &format!("{f}.distance_m"))?,
                                    },
                                    PendulumAttachment::Rod(r) => Attachment::Rod {
                                        mass_kg: req(r.mass_kg, &format!("{f}.mass_kg"))?,
                                        length_m: req(r.length_m, &format!("{f}.length_m"))?,
                                    },
                                })
                            })
                            .collect::<Result<Vec<_>, TraceError>>()
                    })
                    .transpose()?;
                let spec = PendulumSpec {
                    joint,
                    body,
                    attachments,
                    pin_radius_m: num(rig.pin_radius_m),
                    gravity_m_s2: num(rig.gravity_m_s2),
                    initial_rate_deg_s: num(rig.initial_rate_deg_s),
                    body_uncertainty,
                };
                let y = self.channel("alpha_deg").unwrap_or_default().to_vec();
                let release_t_s = Self::release_t_s(test, &t)?;
                spec.joint_test(data, t, y)
                    .map(|(test, baseline)| {
                        (
                            JointTest {
                                release_t_s,
                                ..test
                            },
                            baseline,
                        )
                    })
                    .map_err(rig_err)
            }
            Kind::Slider => {
                if let Some(j) = &self.joint
                    && j != "J8"
                    && j != "custom"
                {
                    return Err(bad(
                        "test.joint",
                        format!("a slider test is of joint J8 (or `custom`), got `{j}`"),
                    ));
                }
                let rig: SliderRig = match &test.rig {
                    Some(m) => wire::read_map(m, "test.rig")?,
                    None => SliderRig::default(),
                };
                // A whole number here; its span (`[rig_limits] springs`, 0 = none) is the
                // models' one rule, checked with the rest of the rig.
                let springs = rig.springs.map(|n| u32::try_from(n).unwrap_or(u32::MAX));
                let spec = SliderSpec {
                    custom: self.joint.as_deref() == Some("custom"),
                    moving_mass_kg: num(rig.moving_mass_kg),
                    springs,
                    spring_stiffness_n_per_mm: num(rig.spring_stiffness_n_per_mm),
                    normal_force_n: num(rig.normal_force_n),
                    moving_mass_sd_kg: num(rig.moving_mass_uncertainty_kg),
                };
                let y = self.channel("h_mm").unwrap_or_default().to_vec();
                let f = self.channel("F_N").map(<[f64]>::to_vec);
                spec.joint_test(data, t, y, f).map_err(rig_err)
            }
            Kind::Lift => Err(bad(
                "test.kind",
                "a lift test is of the whole pantograph: see `lift_channels`",
            )),
            Kind::QuadrangleSwing => Err(bad(
                "test.kind",
                "a quadrangle swing is of four joints together: see `quadrangle_channels`",
            )),
            Kind::StaticForce => Err(bad(
                "test.kind",
                "a static_force test is of the whole pantograph: see `static_force_channels`",
            )),
        }
    }
}
