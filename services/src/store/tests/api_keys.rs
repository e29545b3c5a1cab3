//! API keys: create, verify, revoke.
//! Each case runs on SQLite and on PostgreSQL (`contract!` in `mod.rs`).

use super::*;

pub(super) async fn api_keys_create_verify_revoke(store: &Store) {
    let (reader, secret) = store
        .create_api_key(Role::Reader, "depot")
        .await
        .expect("create");
    let (admin, admin_secret) = store
        .create_api_key(Role::Admin, "ops")
        .await
        .expect("create");
    assert!(secret.starts_with(keys::KEY_TAG));
    assert_eq!(reader.prefix, &secret[..keys::PREFIX_LEN]);
    assert_eq!(
        (reader.role, reader.label.as_str()),
        (Role::Reader, "depot")
    );
    let got = store
        .verify_api_key(&secret)
        .await
        .expect("verify")
        .expect("valid");
    assert_eq!(got, reader);
    let got = store
        .verify_api_key(&admin_secret)
        .await
        .expect("verify")
        .expect("valid");
    assert_eq!(got.role, Role::Admin);
    // Same prefix, wrong tail; garbage; empty.
    let mut wrong = secret.clone();
    let tail = if wrong.ends_with('0') { "1" } else { "0" };
    wrong.replace_range(wrong.len() - 1.., tail);
    assert!(
        store
            .verify_api_key(&wrong)
            .await
            .expect("verify")
            .is_none()
    );
    assert!(store.verify_api_key("pw_").await.expect("verify").is_none());
    assert!(store.verify_api_key("").await.expect("verify").is_none());
    assert!(
        store
            .verify_api_key("Bearer ☃☃☃☃")
            .await
            .expect("verify")
            .is_none()
    );
    // Only the hash is stored.
    let hits: i64 = {
        let sql =
            "SELECT count(*) FROM api_keys WHERE key_sha256 = $1 OR prefix = $1 OR label = $1";
        match store {
            Store::Sqlite(s) => {
                sqlx::query_scalar(sql)
                    .bind(&secret)
                    .fetch_one(s.pool())
                    .await
            }
            Store::Postgres(s) => {
                sqlx::query_scalar(sql)
                    .bind(&secret)
                    .fetch_one(s.pool())
                    .await
            }
        }
        .expect("count")
    };
    assert_eq!(hits, 0);
    assert!(store.revoke_api_key(reader.id).await.expect("revoke"));
    assert!(!store.revoke_api_key(reader.id).await.expect("revoke twice"));
    assert!(!store.revoke_api_key(9999).await.expect("revoke unknown"));
    assert!(
        store
            .verify_api_key(&secret)
            .await
            .expect("verify")
            .is_none()
    );
    assert!(
        store
            .verify_api_key(&admin_secret)
            .await
            .expect("verify")
            .is_some()
    );
    let all = store.list_api_keys().await.expect("list");
    assert_eq!(all.len(), 2);
    assert!(all[0].revoked_at.is_some() && all[1].revoked_at.is_none());
    assert_eq!(all[1], admin);
}
