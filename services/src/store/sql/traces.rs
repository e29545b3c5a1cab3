//! Traces, fits and their curves, the database itself: written once, instantiated by each
//! backend with `traces_impl!();` (see `sql/mod.rs` for the dialect it names).

macro_rules! traces_impl {
    () => {
/// Rewrites the health rows (`joint_latest`, `pantograph_health`) of the trace's pantograph
/// inside the caller's transaction, which has just written a fit of the trace. No other fit of
/// the serial can interleave: SQLite's `BEGIN IMMEDIATE` serialises writers; PostgreSQL locks
/// the pantograph row first (`lock_serial`), so the later fit (READ COMMITTED: a fresh
/// snapshot per statement) sees the earlier one.
async fn refresh_health(conn: &mut Conn, trace_id: &str) -> Result<()> {
    let serial: Option<Option<String>> =
        query_scalar("SELECT serial FROM traces WHERE trace_id = $1")
            .bind(trace_id)
            .fetch_optional(&mut *conn)
            .await?;
    let Some(serial) = serial.flatten() else {
        return Ok(());
    };
    lock_serial(conn, &serial).await?;
    query("DELETE FROM joint_latest WHERE serial = $1")
        .bind(&serial)
        .execute(&mut *conn)
        .await?;
    query(JOINT_LATEST_REFRESH_SQL)
        .bind(&serial)
        .execute(&mut *conn)
        .await?;
    query("DELETE FROM param_evidence WHERE serial = $1")
        .bind(&serial)
        .execute(&mut *conn)
        .await?;
    query(PARAM_EVIDENCE_REFRESH_SQL)
        .bind(&serial)
        .execute(&mut *conn)
        .await?;
    query("UPDATE evidence_version SET version = version + 1 WHERE id = 1")
        .execute(&mut *conn)
        .await?;
    query("DELETE FROM pantograph_health WHERE serial = $1")
        .bind(&serial)
        .execute(&mut *conn)
        .await?;
    query(concat!(
        "INSERT INTO pantograph_health (serial, worst, not_ok)
         SELECT serial,
                max(CASE status WHEN 'alarm' THEN 3 WHEN 'watch' THEN 2 WHEN 'ok' THEN 1 ELSE 0 END), ",
        not_ok_agg!(),
        " FROM joint_latest WHERE serial = $1 GROUP BY serial"
    ))
    .bind(&serial)
    .execute(&mut *conn)
    .await?;
    Ok(())
}

/// Writes the fit for (trace, model version) once, inside the caller's transaction.
async fn insert_fit_tx(
    conn: &mut Conn,
    trace_id: &str,
    model_version: &str,
    fit: &NewFit,
) -> Result<FitWrite> {
    let result = fit.result_json()?;
    let id: Option<i64> = query_scalar(concat!(
        "INSERT INTO fits (trace_id, model_version, result_json, rmse, status, prior_version)
         VALUES ($1, $2, $3",
        jsonb!(),
        ", $4, $5, $6)
         ON CONFLICT (trace_id, model_version) DO NOTHING
         RETURNING id"
    ))
    .bind(trace_id)
    .bind(model_version)
    .bind(result)
    .bind(fit.rmse)
    .bind(fit.status().map(Status::as_str))
    .bind(fit.result.fit.prior.as_ref().map(|p| p.version))
    .fetch_optional(&mut *conn)
    .await?;
    let Some(fit_id) = id else {
        let fit_id: i64 =
            query_scalar("SELECT id FROM fits WHERE trace_id = $1 AND model_version = $2")
                .bind(trace_id)
                .bind(model_version)
                .fetch_one(&mut *conn)
                .await?;
        return Ok(FitWrite {
            fit_id,
            created: false,
        });
    };
    for j in &fit.joints {
        query(
            "INSERT INTO fit_joints (fit_id, joint, viscous, viscous_lo, viscous_hi,
                                     dry, dry_lo, dry_hi, identifiable, status,
                                     viscous_informed, viscous_status, dry_informed, dry_status)
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14)",
        )
        .bind(fit_id)
        .bind(&j.joint)
        .bind(j.viscous)
        .bind(j.viscous_lo)
        .bind(j.viscous_hi)
        .bind(j.dry)
        .bind(j.dry_lo)
        .bind(j.dry_hi)
        .bind(j.identifiable)
        .bind(j.status.as_str())
        .bind(j.viscous_informed)
        .bind(j.viscous_status.map(Status::as_str))
        .bind(j.dry_informed)
        .bind(j.dry_status.map(Status::as_str))
        .execute(&mut *conn)
        .await?;
    }
    if let Some(curve) = &fit.curve {
        let json = serde_json::to_string(curve)
            .map_err(|e| StoreError::Invalid(format!("fit curve: {e}")))?;
        query(concat!(
            "INSERT INTO fit_curves (fit_id, curve_json) VALUES ($1, $2",
            jsonb!(),
            ")"
        ))
            .bind(fit_id)
            .bind(json)
            .execute(&mut *conn)
            .await?;
    }
    refresh_health(conn, trace_id).await?;
    Ok(FitWrite {
        fit_id,
        created: true,
    })
}

impl TraceBackend for Backend {
    async fn ping(&self) -> Result<()> {
        query("SELECT 1").execute(&self.pool).await?;
        Ok(())
    }
    async fn migrations_applied(&self) -> Result<bool> {
        let mut conn = self.pool.acquire().await?;
        let table = &MIGRATOR.table_name;
        if conn.dirty_version(table).await?.is_some() {
            return Ok(false);
        }
        let applied = conn.list_applied_migrations(table).await?;
        Ok(MIGRATOR
            .iter()
            .filter(|m| m.migration_type.is_up_migration())
            .all(|m| {
                applied
                    .iter()
                    .any(|a| a.version == m.version && a.checksum == m.checksum)
            }))
    }
    async fn insert_trace(&self, t: PreparedTrace) -> Result<InsertOutcome> {
        let mut tx = self.begin().await?;
        let existing: Option<String> =
            query_scalar("SELECT content_sha256 FROM traces WHERE trace_id = $1")
                .bind(&t.trace_id)
                .fetch_optional(&mut *tx)
                .await?;
        if let Some(sha) = existing {
            tx.rollback().await?;
            return Ok(if sha == t.content_sha256 {
                InsertOutcome::Existing {
                    trace_id: t.trace_id,
                }
            } else {
                InsertOutcome::Conflict {
                    trace_id: t.trace_id,
                }
            });
        }
        query("INSERT INTO vehicles (id) VALUES ($1) ON CONFLICT (id) DO NOTHING")
            .bind(&t.vehicle_id)
            .execute(&mut *tx)
            .await?;
        let recorded = ts(t.recorded_at);
        if let Some(serial) = &t.serial {
            query("INSERT INTO pantographs (serial, model) VALUES ($1, $2) ON CONFLICT (serial) DO NOTHING")
                .bind(serial)
                .bind(&t.model)
                .execute(&mut *tx)
                .await?;
            // Serialise uploads of the same pantograph while its mount history is decided.
            lock_serial(&mut tx, serial).await?;
            let in_effect = mount_row(
                query(
                    "SELECT vehicle_id, since FROM pantograph_mounts
                     WHERE serial = $1 AND since <= $2 ORDER BY since DESC LIMIT 1",
                )
                .bind(serial)
                .bind(&recorded)
                .fetch_optional(&mut *tx)
                .await?,
            )?;
            let next = mount_row(
                query(
                    "SELECT vehicle_id, since FROM pantograph_mounts
                     WHERE serial = $1 AND since > $2 ORDER BY since ASC LIMIT 1",
                )
                .bind(serial)
                .bind(&recorded)
                .fetch_optional(&mut *tx)
                .await?,
            )?;
            let action = mount_action(
                &t.vehicle_id,
                t.recorded_at,
                in_effect.as_ref().map(|(v, s)| (v.as_str(), *s)),
                next.as_ref().map(|(v, s)| (v.as_str(), *s)),
            );
            match action {
                MountAction::Keep => {}
                MountAction::Insert => {
                    query(
                        "INSERT INTO pantograph_mounts (serial, vehicle_id, since) VALUES ($1, $2, $3)",
                    )
                    .bind(serial)
                    .bind(&t.vehicle_id)
                    .bind(&recorded)
                    .execute(&mut *tx)
                    .await?;
                }
                MountAction::MoveNext { since } => {
                    query(
                        "UPDATE pantograph_mounts SET since = $1 WHERE serial = $2 AND since = $3",
                    )
                    .bind(&recorded)
                    .bind(serial)
                    .bind(ts(since))
                    .execute(&mut *tx)
                    .await?;
                }
            }
        }
        let inserted = query(
            "INSERT INTO traces (trace_id, vehicle_id, serial, model, recorded_at, kind, joint,
                                 test_json, content_sha256, samples, sample_count, channel_names)
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12)
             ON CONFLICT (trace_id) DO NOTHING",
        )
        .bind(&t.trace_id)
        .bind(&t.vehicle_id)
        .bind(&t.serial)
        .bind(&t.model)
        .bind(&recorded)
        .bind(&t.kind)
        .bind(&t.joint)
        .bind(&t.test_json)
        .bind(&t.content_sha256)
        .bind(&t.samples)
        .bind(t.sample_count)
        .bind(&t.channel_names)
        .execute(&mut *tx)
        .await?
        .rows_affected();
        if inserted == 0 {
            // A concurrent upload of the same id committed first (PostgreSQL; SQLite's
            // `BEGIN IMMEDIATE` found it above): answer as if it were earlier.
            tx.rollback().await?;
            let sha: String = query_scalar("SELECT content_sha256 FROM traces WHERE trace_id = $1")
                .bind(&t.trace_id)
                .fetch_one(&self.pool)
                .await?;
            return Ok(if sha == t.content_sha256 {
                InsertOutcome::Existing {
                    trace_id: t.trace_id,
                }
            } else {
                InsertOutcome::Conflict {
                    trace_id: t.trace_id,
                }
            });
        }
        let job_id: Option<i64> = query_scalar(
            "INSERT INTO jobs (trace_id, model_version) VALUES ($1, $2)
             ON CONFLICT DO NOTHING RETURNING id",
        )
        .bind(&t.trace_id)
        .bind(&t.model_version)
        .fetch_optional(&mut *tx)
        .await?;
        tx.commit().await?;
        Ok(InsertOutcome::Created {
            trace_id: t.trace_id,
            job_id,
        })
    }
    async fn get_trace(&self, id: &str) -> Result<Option<TraceMeta>> {
        query(
concat!(
            "SELECT trace_id, vehicle_id, serial, model, recorded_at, kind, joint, test_json,
                    content_sha256, sample_count, channel_names, ",
            blob_len!(),
            " AS samples_bytes, created_at
             FROM traces WHERE trace_id = $1"
        ))
        .bind(id)
        .fetch_optional(&self.pool)
        .await?
        .map(|r| trace_from(&r))
        .transpose()
    }
    async fn samples_blob(&self, id: &str) -> Result<Option<Vec<u8>>> {
        Ok(
            query_scalar("SELECT samples FROM traces WHERE trace_id = $1")
                .bind(id)
                .fetch_optional(&self.pool)
                .await?,
        )
    }
    async fn insert_fit(
        &self,
        trace_id: &str,
        model_version: &str,
        fit: &NewFit,
    ) -> Result<FitWrite> {
        let mut tx = self.begin().await?;
        let w = insert_fit_tx(&mut tx, trace_id, model_version, fit).await?;
        tx.commit().await?;
        Ok(w)
    }
    async fn fit_curve(&self, fit_id: i64) -> Result<Option<FitCurve>> {
        let json: Option<String> =
            query_scalar("SELECT CAST(curve_json AS TEXT) FROM fit_curves WHERE fit_id = $1")
                .bind(fit_id)
                .fetch_optional(&self.pool)
                .await?;
        json.map(|j| {
            serde_json::from_str(&j)
                .map_err(|e| StoreError::Corrupt(format!("fit {fit_id}: curve: {e}")))
        })
        .transpose()
    }
    async fn get_fit(&self, trace_id: &str) -> Result<Option<FitRecord>> {
        let Some(row) = query(
            "SELECT id, trace_id, model_version, created_at,
                    CAST(result_json AS TEXT) AS result_json, rmse, status
             FROM fits WHERE trace_id = $1 ORDER BY id DESC LIMIT 1",
        )
        .bind(trace_id)
        .fetch_optional(&self.pool)
        .await?
        else {
            return Ok(None);
        };
        let joints = query(
            "SELECT joint, viscous, viscous_lo, viscous_hi, dry, dry_lo, dry_hi, identifiable, status,
                    viscous_informed, viscous_status, dry_informed, dry_status
             FROM fit_joints WHERE fit_id = $1 ORDER BY joint",
        )
        .bind(row.int("id")?)
        .fetch_all(&self.pool)
        .await?
        .iter()
        .map(joint_fit_from)
        .collect::<Result<Vec<_>>>()?;
        fit_from(&row, joints).map(Some)
    }
    async fn counts(&self) -> Result<Counts> {
        let r = query(COUNTS_SQL).fetch_one(&self.pool).await?;
        counts_from(&r)
    }
    async fn pantograph_model(&self, serial: &str) -> Result<Option<String>> {
        Ok(
            query_scalar::<_, String>("SELECT model FROM pantographs WHERE serial = $1")
                .bind(serial)
                .fetch_optional(&self.pool)
                .await?,
        )
    }
    async fn pantograph_exists(&self, serial: &str) -> Result<bool> {
        let n: i64 = query_scalar("SELECT count(*) FROM pantographs WHERE serial = $1")
            .bind(serial)
            .fetch_one(&self.pool)
            .await?;
        Ok(n > 0)
    }
    async fn close(&self) {
        self.pool.close().await;
    }

    async fn latest_trace_of_kind(&self, serial: &str, kind: &str) -> Result<Option<TraceMeta>> {
        query(
concat!(
            "SELECT trace_id, vehicle_id, serial, model, recorded_at, kind, joint, test_json,
                    content_sha256, sample_count, channel_names, ",
            blob_len!(),
            " AS samples_bytes, created_at
             FROM traces WHERE serial = $1 AND kind = $2
             ORDER BY recorded_at DESC, trace_id DESC LIMIT 1"
        ))
        .bind(serial)
        .bind(kind)
        .fetch_optional(&self.pool)
        .await?
        .map(|r| trace_from(&r))
        .transpose()
    }

    async fn traces_of_kind(
        &self,
        serial: &str,
        kind: &str,
        limit: i64,
    ) -> Result<Vec<TraceMeta>> {
        query(
concat!(
            "SELECT trace_id, vehicle_id, serial, model, recorded_at, kind, joint, test_json,
                    content_sha256, sample_count, channel_names, ",
            blob_len!(),
            " AS samples_bytes, created_at
             FROM traces WHERE serial = $1 AND kind = $2
             ORDER BY recorded_at DESC, trace_id DESC LIMIT $3"
        ))
        .bind(serial)
        .bind(kind)
        .bind(limit)
        .fetch_all(&self.pool)
        .await?
        .iter()
        .map(trace_from)
        .collect()
    }
}
    };
}
