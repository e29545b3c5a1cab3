//! Vehicles, joint history, joint states and fleet health: written once, instantiated by each
//! backend with `health_impl!();` (see `sql/mod.rs` for the dialect it names).

macro_rules! health_impl {
    () => {
impl HealthBackend for Backend {
    async fn list_vehicles(&self) -> Result<Vec<VehicleSummary>> {
        query(concat!(
            "SELECT v.id, v.created_at,
                    (SELECT count(*) FROM pantograph_mounts m
                     WHERE m.vehicle_id = v.id AND ",
            current_mount!(),
            ") AS pantographs,
                    (SELECT count(*) FROM traces t WHERE t.vehicle_id = v.id) AS traces,
                    (SELECT max(t.recorded_at) FROM traces t WHERE t.vehicle_id = v.id) AS last_test
             FROM vehicles v ORDER BY v.id"
        ))
        .fetch_all(&self.pool)
        .await?
        .iter()
        .map(vehicle_from)
        .collect()
    }
    async fn get_vehicle(&self, id: &str) -> Result<Option<VehicleDetail>> {
        let Some(v) = query("SELECT id, created_at FROM vehicles WHERE id = $1")
            .bind(id)
            .fetch_optional(&self.pool)
            .await?
        else {
            return Ok(None);
        };
        let mounted = query(concat!(
            "SELECT p.serial, p.model, m.since,
                    (SELECT max(t.recorded_at) FROM traces t WHERE t.serial = p.serial) AS last_test
             FROM pantograph_mounts m JOIN pantographs p ON p.serial = m.serial
             WHERE m.vehicle_id = $1 AND ",
            current_mount!(),
            " ORDER BY p.serial"
        ))
        .bind(id)
        .fetch_all(&self.pool)
        .await?;
        let mut points = query(concat!(
            points_cte!(
                "AND t.serial IN (SELECT m.serial FROM pantograph_mounts m
                                  WHERE m.vehicle_id = $1 AND
                                  m.since = (SELECT max(m2.since) FROM pantograph_mounts m2
                                             WHERE m2.serial = m.serial))"
            ),
            // Each joint's point is the fit that decides its health (`joint_latest`), with the
            // joint's state as fleet health and the alerts see it.
            "SELECT pts.serial, pts.vehicle_id, pts.trace_id, pts.recorded_at, pts.model_version,
                    pts.fit_id, pts.fitted_at, pts.joint, pts.viscous, pts.viscous_lo,
                    pts.viscous_hi, pts.dry, pts.dry_lo, pts.dry_hi, l.identifiable, l.status,
                    pts.viscous_informed, pts.viscous_status, pts.dry_informed, pts.dry_status
             FROM pts JOIN joint_latest l
               ON l.serial = pts.serial AND l.joint = pts.joint AND l.trace_id = pts.trace_id
             ORDER BY pts.serial, pts.joint"
        ))
        .bind(id)
        .fetch_all(&self.pool)
        .await?
        .iter()
        .map(|r| Ok((r.text("serial")?, joint_point_from(r)?)))
        .collect::<Result<Vec<_>>>()?;
        let mut pantographs = Vec::with_capacity(mounted.len());
        for m in &mounted {
            let serial = m.text("serial")?;
            let joints = points
                .extract_if(.., |(s, _)| *s == serial)
                .map(|(_, p)| p)
                .collect();
            let states = self.joint_states(&serial).await?;
            pantographs.push(pantograph_state(
                serial,
                m.text("model")?,
                m.ts("since")?,
                m.opt_ts("last_test")?,
                joints,
                states,
            ));
        }
        Ok(Some(VehicleDetail {
            vehicle_id: v.text("id")?,
            created_at: v.ts("created_at")?,
            pantographs,
        }))
    }
    async fn joint_history(&self, serial: &str, joint: &str) -> Result<Vec<JointPoint>> {
        query(concat!(
            points_cte!("AND t.serial = $1 AND j.joint = $2"),
            "SELECT * FROM pts ORDER BY recorded_at, trace_id"
        ))
        .bind(serial)
        .bind(joint)
        .fetch_all(&self.pool)
        .await?
        .iter()
        .map(joint_point_from)
        .collect()
    }
    async fn fleet_health(&self, filter: &FleetFilter, page: Page) -> Result<FleetPage> {
        let rank = filter.status.map(Status::rank);
        // One statement: the page, the total over all pages (a window count before the limit),
        // and `last_test` looked up for the page's rows only.
        let found = query(concat!(
            fleet_sql!(),
            ", page AS (
                SELECT fleet.*, count(*) OVER () AS total FROM fleet
                ORDER BY worst DESC NULLS LAST, serial LIMIT $3 OFFSET $4
            )
            SELECT page.*,
                   (SELECT max(t.recorded_at) FROM traces t WHERE t.serial = page.serial)
                       AS last_test
            FROM page ORDER BY worst DESC NULLS LAST, serial"
        ))
        .bind(rank)
        .bind(&filter.vehicle_id)
        .bind(i64::from(page.limit))
        .bind(i64::try_from(page.offset).unwrap_or(i64::MAX))
        .fetch_all(&self.pool)
        .await?;
        let total: i64 = match found.first() {
            Some(r) => r.int("total")?,
            // Past the last page (or nothing matches): the total needs its own count.
            None => {
                query_scalar(concat!(fleet_sql!(), "SELECT count(*) FROM fleet"))
                    .bind(rank)
                    .bind(&filter.vehicle_id)
                    .fetch_one(&self.pool)
                    .await?
            }
        };
        let rows = found
            .iter()
            .map(fleet_row_from)
            .collect::<Result<Vec<_>>>()?;
        Ok(FleetPage {
            total: u64::try_from(total).unwrap_or(0),
            rows,
        })
    }
    async fn joint_states(&self, serial: &str) -> Result<Vec<JointState>> {
        query(JOINT_STATES_SQL)
            .bind(serial)
            .fetch_all(&self.pool)
            .await?
            .iter()
            .map(joint_state_from)
            .collect()
    }
    async fn param_evidence(&self, serial: Option<&str>) -> Result<Vec<EvidenceRow>> {
        query(PARAM_EVIDENCE_SQL)
            .bind(serial)
            .fetch_all(&self.pool)
            .await?
            .iter()
            .map(evidence_row_from)
            .collect()
    }
    async fn latest_test_at(&self, serial: &str) -> Result<Option<DateTime<Utc>>> {
        query("SELECT max(recorded_at) AS last_test FROM traces WHERE serial = $1")
            .bind(serial)
            .fetch_one(&self.pool)
            .await?
            .opt_ts("last_test")
    }
    async fn set_param_trends(
        &self,
        serial: &str,
        trends: &[(String, String, Option<StoredTrend>)],
    ) -> Result<()> {
        let mut tx = self.begin().await?;
        for (joint, param, trend) in trends {
            query(
                "UPDATE param_evidence SET slope_per_day = $4, slope_lo_per_day = $5,
                        slope_hi_per_day = $6, slope_significant = $7
                 WHERE serial = $1 AND joint = $2 AND param = $3",
            )
            .bind(serial)
            .bind(joint)
            .bind(param)
            .bind(trend.map(|t| t.slope_per_day))
            .bind(trend.map(|t| t.slope_ci95[0]))
            .bind(trend.map(|t| t.slope_ci95[1]))
            .bind(trend.map(|t| t.significant))
            .execute(&mut *tx)
            .await?;
        }
        query("UPDATE evidence_version SET version = version + 1 WHERE id = 1")
            .execute(&mut *tx)
            .await?;
        tx.commit().await?;
        Ok(())
    }
    async fn evidence_version(&self) -> Result<i64> {
        query("SELECT version FROM evidence_version WHERE id = 1")
            .fetch_optional(&self.pool)
            .await?
            .map_or(Ok(0), |r| r.int("version"))
    }
    async fn serial_history(&self, serial: &str) -> Result<Vec<JointPoint>> {
        query(
            "WITH cur AS (
                SELECT f.id, f.trace_id, f.model_version, f.created_at
                FROM fits f
                WHERE f.id = (SELECT max(f2.id) FROM fits f2 WHERE f2.trace_id = f.trace_id)
            )
            SELECT t.trace_id, t.vehicle_id, t.recorded_at, cur.model_version,
                   cur.id AS fit_id, cur.created_at AS fitted_at,
                   j.joint, j.viscous, j.viscous_lo, j.viscous_hi, j.dry, j.dry_lo, j.dry_hi,
                   j.identifiable, j.status, j.viscous_informed, j.viscous_status,
                   j.dry_informed, j.dry_status
            FROM cur
            JOIN traces t ON t.trace_id = cur.trace_id
            JOIN fit_joints j ON j.fit_id = cur.id
            WHERE t.serial = $1
            ORDER BY t.recorded_at, t.trace_id, j.joint",
        )
        .bind(serial)
        .fetch_all(&self.pool)
        .await?
        .iter()
        .map(joint_point_from)
        .collect()
    }
}

#[cfg(test)]
impl Backend {
    /// The fleet health by the window over every fit (the pre-0004 query), for the tests.
    pub(crate) async fn fleet_health_by_window(
        &self,
        filter: &FleetFilter,
        page: Page,
    ) -> Result<FleetPage> {
        let rank = filter.status.map(Status::rank);
        let total: i64 = query_scalar(concat!(fleet_cte!(), "SELECT count(*) FROM fleet"))
            .bind(rank)
            .bind(&filter.vehicle_id)
            .fetch_one(&self.pool)
            .await?;
        let rows = query(concat!(
            fleet_cte!(),
            "SELECT * FROM fleet ORDER BY worst DESC NULLS LAST, serial LIMIT $3 OFFSET $4"
        ))
        .bind(rank)
        .bind(&filter.vehicle_id)
        .bind(i64::from(page.limit))
        .bind(i64::try_from(page.offset).unwrap_or(i64::MAX))
        .fetch_all(&self.pool)
        .await?
        .iter()
        .map(fleet_row_from)
        .collect::<Result<Vec<_>>>()?;
        Ok(FleetPage {
            total: u64::try_from(total).unwrap_or(0),
            rows,
        })
    }

    /// Each joint's latest state by the window (left) and from `joint_latest` (right), sorted.
    pub(crate) async fn latest_both_ways(&self) -> Result<(Vec<LatestRow>, Vec<LatestRow>)> {
        let window = query(concat!(
            "SELECT serial, joint, trace_id, fit_id, status FROM (",
            joint_state_select!("t.serial IS NOT NULL"),
            ") s ORDER BY serial, joint"
        ))
        .fetch_all(&self.pool)
        .await?;
        let table = query(
            "SELECT serial, joint, trace_id, fit_id, status FROM joint_latest ORDER BY serial, joint",
        )
        .fetch_all(&self.pool)
        .await?;
        let rows = |v: Vec<DbRow>| -> Result<Vec<LatestRow>> {
            v.iter()
                .map(|r| {
                    Ok((
                        r.text("serial")?,
                        r.text("joint")?,
                        r.text("trace_id")?,
                        r.int("fit_id")?,
                        r.text("status")?,
                    ))
                })
                .collect()
        };
        Ok((rows(window)?, rows(table)?))
    }
}
    };
}
