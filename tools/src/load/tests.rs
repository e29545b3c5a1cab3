use super::*;

#[test]
fn percentiles_are_nearest_rank() {
    let l = latency((1..=100).map(f64::from).collect());
    assert_eq!(
        l,
        Latency {
            p50_ms: 50.0,
            p90_ms: 90.0,
            p99_ms: 99.0,
            max_ms: 100.0
        }
    );
    assert_eq!(latency(vec![]), Latency::default());
    assert_eq!(latency(vec![7.0]).p99_ms, 7.0);
}

#[test]
fn documents_are_valid_distinct_and_reproducible() {
    let base = BaseTrace::new(0.5, 100.0).expect("base");
    let (b1, e1) = make_doc("r1", 0, 0, &base).expect("doc");
    let (b2, e2) = make_doc("r1", 0, 1, &base).expect("doc");
    let (_, e3) = make_doc("r1", 1, 0, &base).expect("doc");
    let (b1_again, e1_again) = make_doc("r1", 0, 0, &base).expect("doc");
    assert_eq!(b1, b1_again);
    assert_eq!(e1.samples_sha256, e1_again.samples_sha256);
    assert_ne!(e1.samples_sha256, e2.samples_sha256);
    assert_ne!(e1.content_sha256, e3.content_sha256);
    assert_ne!(e1.vehicle_id, e3.vehicle_id);
    assert_ne!(b1, b2);
    // The server's hash of the body is the one expected.
    let parsed = pantowatch::ingest::parse_body_blocking(pantowatch::ingest::BodyFormat::Json, &b1)
        .expect("valid upload");
    assert_eq!(parsed.sha256, e1.content_sha256);
    assert_eq!(e1.sample_count, 51);
}

#[test]
fn samples_hash_sees_one_bit_and_the_names() {
    let a = [1.0, 2.0];
    let b = [1.0, f64::from_bits(2.0f64.to_bits() ^ 1)];
    let h = |n: &str, v: &[f64]| samples_sha256([("t_s", &[0.0, 1.0][..]), (n, v)]);
    assert_ne!(h("alpha_deg", &a), h("alpha_deg", &b));
    assert_ne!(h("alpha_deg", &a), h("beta_deg", &a));
    assert_eq!(h("alpha_deg", &a), h("alpha_deg", &a));
}

#[test]
fn run_ids_are_checked() {
    assert!(check_run_id("load-1a2b").is_ok());
    for bad in ["", "a b", "x/y", &"r".repeat(65)] {
        let e = check_run_id(bad).unwrap_err().to_string();
        assert!(e.contains("--run-id"), "{e}");
    }
}
