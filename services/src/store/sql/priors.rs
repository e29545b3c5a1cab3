//! Fleet priors (issue 37, point 3): the versions and their rows, and the refits a new version
//! queues; written once, instantiated by each backend with `priors_impl!();`.

macro_rules! priors_impl {
    () => {
impl PriorBackend for Backend {
    async fn fleet_prior(&self, model: &str, version: Option<i64>) -> Result<Option<StoredPrior>> {
        let Some(h) = query(
            "SELECT version, model, learned_at, source, n_units, floor_relative_sd, fit_sd_scale
             FROM fleet_priors
             WHERE model = $1 AND (CAST($2 AS BIGINT) IS NULL OR version = CAST($2 AS BIGINT))
             ORDER BY version DESC LIMIT 1",
        )
        .bind(model)
        .bind(version)
        .fetch_optional(&self.pool)
        .await?
        else {
            return Ok(None);
        };
        let v = h.int("version")?;
        let rows = query(
            "SELECT joint, param, mean_ratio, sd_ratio, spread_ratio, n_fits, learned
             FROM fleet_prior_params WHERE version = $1 ORDER BY joint, param",
        )
        .bind(v)
        .fetch_all(&self.pool)
        .await?;
        let params = rows
            .iter()
            .map(prior_param_from)
            .collect::<Result<Vec<_>>>()?;
        Ok(Some(StoredPrior {
            version: v,
            model: h.text("model")?,
            learned_at: h.ts("learned_at")?,
            source: h.text("source")?,
            n_units: h.int("n_units")?,
            floor_relative_sd: h.opt_real("floor_relative_sd")?.unwrap_or(f64::NAN),
            fit_sd_scale: h.opt_real("fit_sd_scale")?.unwrap_or(f64::NAN),
            params,
        }))
    }
    async fn publish_fleet_prior(
        &self,
        p: &NewPrior,
        kinds: &[&str],
        refit_prefix: &str,
    ) -> Result<Published> {
        let mut tx = self.begin().await?;
        // Publishers of one type queue behind each other (PostgreSQL: an advisory lock; SQLite's
        // `BEGIN IMMEDIATE` holds the write lock already).
        lock_alert_pair(&mut tx, "fleet_prior", &p.model).await?;
        let version: i64 =
            query_scalar("SELECT COALESCE(max(version), 0) + 1 FROM fleet_priors")
                .fetch_one(&mut *tx)
                .await?;
        query(
            "INSERT INTO fleet_priors (version, model, source, n_units, floor_relative_sd, fit_sd_scale)
             VALUES ($1, $2, $3, $4, $5, $6)",
        )
        .bind(version)
        .bind(&p.model)
        .bind(&p.source)
        .bind(p.n_units)
        .bind(p.floor_relative_sd)
        .bind(p.fit_sd_scale)
        .execute(&mut *tx)
        .await?;
        for q in &p.params {
            query(
                "INSERT INTO fleet_prior_params (version, joint, param, mean_ratio, sd_ratio,
                                                 spread_ratio, n_fits, learned)
                 VALUES ($1, $2, $3, $4, $5, $6, $7, $8)",
            )
            .bind(version)
            .bind(&q.joint)
            .bind(&q.kind)
            .bind(q.mean_ratio)
            .bind(q.sd_ratio)
            .bind(q.spread_ratio)
            .bind(q.n_fits as i64)
            .bind(q.learned)
            .execute(&mut *tx)
            .await?;
        }
        let refit_version = format!("{refit_prefix}{version}");
        let mut queued = 0;
        for kind in kinds {
            queued += query(
                "INSERT INTO jobs (trace_id, model_version)
                 SELECT t.trace_id, CAST($1 AS TEXT) FROM traces t
                 JOIN pantographs p ON p.serial = t.serial
                 JOIN fits f ON f.trace_id = t.trace_id
                            AND f.id = (SELECT max(f2.id) FROM fits f2 WHERE f2.trace_id = t.trace_id)
                 WHERE t.kind = $2 AND p.model = $3
                   AND COALESCE(f.prior_version, 0) < $4
                   AND NOT EXISTS (SELECT 1 FROM fits f3
                                   WHERE f3.trace_id = t.trace_id AND f3.model_version = $1)
                 ORDER BY t.recorded_at, t.trace_id
                 ON CONFLICT DO NOTHING",
            )
            .bind(&refit_version)
            .bind(*kind)
            .bind(&p.model)
            .bind(version)
            .execute(&mut *tx)
            .await?
            .rows_affected();
        }
        tx.commit().await?;
        let prior = self
            .fleet_prior(&p.model, Some(version))
            .await?
            .ok_or_else(|| StoreError::Invalid(format!("fleet prior {version} not read back")))?;
        Ok(Published { prior, queued })
    }
}
    };
}
