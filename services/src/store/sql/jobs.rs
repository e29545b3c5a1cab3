//! The fit queue: enqueue, lease, complete, fail, release (the claim itself is each backend's
//! `claim_job`: its locking differs); written once, instantiated with `jobs_impl!();`.

macro_rules! jobs_impl {
    () => {
impl JobBackend for Backend {
    async fn enqueue(&self, trace_id: &str, model_version: &str) -> Result<Option<i64>> {
        let mut tx = self.begin().await?;
        let id: Option<i64> = query_scalar(
            "INSERT INTO jobs (trace_id, model_version)
             SELECT CAST($1 AS TEXT), CAST($2 AS TEXT) WHERE NOT EXISTS
                (SELECT 1 FROM fits WHERE trace_id = $1 AND model_version = $2)
             ON CONFLICT DO NOTHING RETURNING id",
        )
        .bind(trace_id)
        .bind(model_version)
        .fetch_optional(&mut *tx)
        .await?;
        tx.commit().await?;
        Ok(id)
    }
    async fn claim(&self, worker: &str, lease: Duration) -> Result<Option<Job>> {
        self.claim_job(worker, lease).await
    }
    async fn complete(&self, job_id: i64, worker: &str, fit: &NewFit) -> Result<CompleteOutcome> {
        let mut tx = self.begin().await?;
        let Some(job) = query(concat!(
            "SELECT trace_id, model_version FROM jobs
             WHERE id = $1 AND state = 'running' AND worker = $2",
            for_update!()
        ))
        .bind(job_id)
        .bind(worker)
        .fetch_optional(&mut *tx)
        .await?
        else {
            tx.rollback().await?;
            return Ok(CompleteOutcome::LeaseLost);
        };
        let w = insert_fit_tx(
            &mut tx,
            &job.text("trace_id")?,
            &job.text("model_version")?,
            fit,
        )
        .await?;
        query(concat!(
            "UPDATE jobs SET state = 'done', lease_until = NULL, last_error = NULL, updated_at = ",
            now!(),
            " WHERE id = $1"
        ))
        .bind(job_id)
        .execute(&mut *tx)
        .await?;
        tx.commit().await?;
        Ok(CompleteOutcome::Completed(w))
    }
    async fn fail(
        &self,
        job_id: i64,
        worker: &str,
        error: &str,
        retry: bool,
    ) -> Result<FailOutcome> {
        let mut tx = self.begin().await?;
        let Some(attempts): Option<i64> = query_scalar(concat!(
            "SELECT attempts FROM jobs WHERE id = $1 AND state = 'running' AND worker = $2",
            for_update!()
        ))
        .bind(job_id)
        .bind(worker)
        .fetch_optional(&mut *tx)
        .await?
        else {
            tx.rollback().await?;
            return Ok(FailOutcome::LeaseLost);
        };
        let outcome = if retry && attempts < MAX_ATTEMPTS {
            FailOutcome::Requeued
        } else {
            FailOutcome::Failed
        };
        let state = match outcome {
            FailOutcome::Requeued => JobState::Queued,
            _ => JobState::Failed,
        };
        query(concat!(
            "UPDATE jobs SET state = $2, lease_until = NULL, last_error = $3, updated_at = ",
            now!(),
            " WHERE id = $1"
        ))
        .bind(job_id)
        .bind(state.as_str())
        .bind(error)
        .execute(&mut *tx)
        .await?;
        tx.commit().await?;
        Ok(outcome)
    }
    async fn release(&self, job_id: i64, worker: &str) -> Result<bool> {
        // The claim counted an attempt; a release is not a failure, so it is given back.
        let n = query(concat!(
            "UPDATE jobs SET state = 'queued', attempts = CASE WHEN attempts > 0 THEN attempts - 1 ELSE 0 END, worker = NULL,
                             lease_until = NULL, updated_at = ",
            now!(),
            " WHERE id = $1 AND state = 'running' AND worker = $2"
        ))
        .bind(job_id)
        .bind(worker)
        .execute(&self.pool)
        .await?
        .rows_affected();
        Ok(n == 1)
    }
    async fn release_counted(&self, job_id: i64, worker: &str) -> Result<Option<JobState>> {
        // Its fit had started: the attempt the claim counted stays counted, so a fit that
        // outlasts every shutdown cannot loop for ever; at the limit the job fails (issue 18).
        let state: Option<String> = query_scalar(concat!(
            "UPDATE jobs SET state = CASE WHEN attempts >= $3 THEN 'failed' ELSE 'queued' END,
                             last_error = CASE WHEN attempts >= $3
                                 THEN 'stopped by a shutdown during each of its ' || attempts
                                      || ' attempts: its fit outlasts worker.shutdown_grace_ms'
                                 ELSE last_error END,
                             worker = NULL, lease_until = NULL, updated_at = ",
            now!(),
            " WHERE id = $1 AND state = 'running' AND worker = $2 RETURNING state"
        ))
        .bind(job_id)
        .bind(worker)
        .bind(MAX_ATTEMPTS)
        .fetch_optional(&self.pool)
        .await?;
        state.map(|s| s.parse()).transpose()
    }
    async fn renew_lease(&self, job_id: i64, worker: &str, lease: Duration) -> Result<bool> {
        let n = query(concat!(
            "UPDATE jobs SET lease_until = ",
            lease_until!(),
            ", updated_at = ",
            now!(),
            " WHERE id = $1 AND state = 'running' AND worker = $2"
        ))
        .bind(job_id)
        .bind(worker)
        .bind(lease_param(lease))
        .execute(&self.pool)
        .await?
        .rows_affected();
        Ok(n == 1)
    }
    async fn requeue(&self, vehicle_id: Option<&str>, model_version: &str) -> Result<u64> {
        let mut tx = self.begin().await?;
        let n = query(
            "INSERT INTO jobs (trace_id, model_version)
             SELECT t.trace_id, $1 FROM traces t
             WHERE (CAST($2 AS TEXT) IS NULL OR t.vehicle_id = CAST($2 AS TEXT))
               AND NOT EXISTS (SELECT 1 FROM fits f
                               WHERE f.trace_id = t.trace_id AND f.model_version = $1)
             ORDER BY t.recorded_at, t.trace_id
             ON CONFLICT DO NOTHING",
        )
        .bind(model_version)
        .bind(vehicle_id)
        .execute(&mut *tx)
        .await?
        .rows_affected();
        tx.commit().await?;
        Ok(n)
    }
    async fn get_job(&self, id: i64) -> Result<Option<Job>> {
        query(concat!("SELECT", job_cols!(), "FROM jobs WHERE id = $1"))
            .bind(id)
            .fetch_optional(&self.pool)
            .await?
            .map(|r| job_from(&r))
            .transpose()
    }
    async fn latest_job(&self, trace_id: &str) -> Result<Option<Job>> {
        query(concat!(
            "SELECT",
            job_cols!(),
            "FROM jobs WHERE trace_id = $1 ORDER BY id DESC LIMIT 1"
        ))
        .bind(trace_id)
        .fetch_optional(&self.pool)
        .await?
        .map(|r| job_from(&r))
        .transpose()
    }
    async fn job_counts(&self) -> Result<JobCounts> {
        let mut c = JobCounts::default();
        for r in query("SELECT state, count(*) AS n FROM jobs GROUP BY state")
            .fetch_all(&self.pool)
            .await?
        {
            let n = r.int("n")?;
            match parse_enum::<JobState>(&r.text("state")?)? {
                JobState::Queued => c.queued = n,
                JobState::Running => c.running = n,
                JobState::Done => c.done = n,
                JobState::Failed => c.failed = n,
            }
        }
        Ok(c)
    }
    async fn queue_stats(&self) -> Result<QueueStats> {
        let r = query(concat!(
            "SELECT (SELECT ",
            queued_age!(),
            " FROM jobs WHERE state = 'queued') AS age,
                    (SELECT count(*) FROM webhook_deliveries WHERE state = 'pending') AS backlog"
        ))
        .fetch_one(&self.pool)
        .await?;
        Ok(QueueStats {
            oldest_queued_age_s: r.try_get::<Option<f64>, _>("age")?,
            outbox_backlog: r.try_get::<i64, _>("backlog")?,
        })
    }
}
    };
}
