//! API keys: written once, instantiated by each backend with `keys_impl!();`
//! (see `sql/mod.rs` for the dialect it names).

macro_rules! keys_impl {
    () => {
impl KeyBackend for Backend {
    async fn insert_api_key(
        &self,
        prefix: &str,
        hash: &str,
        role: Role,
        label: &str,
    ) -> Result<ApiKey> {
        let r = query(
            "INSERT INTO api_keys (prefix, key_sha256, role, label) VALUES ($1, $2, $3, $4)
             RETURNING id, prefix, role, label, created_at, revoked_at",
        )
        .bind(prefix)
        .bind(hash)
        .bind(role.as_str())
        .bind(label)
        .fetch_one(&self.pool)
        .await?;
        api_key_from(&r)
    }
    async fn keys_by_prefix(&self, prefix: &str) -> Result<Vec<(ApiKey, String)>> {
        self.key_lookups
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        query(
            "SELECT id, prefix, role, label, created_at, revoked_at, key_sha256 FROM api_keys
             WHERE prefix = $1 AND revoked_at IS NULL",
        )
        .bind(prefix)
        .fetch_all(&self.pool)
        .await?
        .iter()
        .map(|r| Ok((api_key_from(r)?, r.text("key_sha256")?)))
        .collect()
    }
    async fn revoke_api_key(&self, id: i64) -> Result<bool> {
        let n = query(concat!(
            "UPDATE api_keys SET revoked_at = ",
            now!(),
            " WHERE id = $1 AND revoked_at IS NULL"
        ))
        .bind(id)
        .execute(&self.pool)
        .await?
        .rows_affected();
        Ok(n > 0)
    }
    async fn list_api_keys(&self) -> Result<Vec<ApiKey>> {
        query("SELECT id, prefix, role, label, created_at, revoked_at FROM api_keys ORDER BY id")
            .fetch_all(&self.pool)
            .await?
            .iter()
            .map(api_key_from)
            .collect()
    }
}
    };
}
