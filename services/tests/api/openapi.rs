//! The OpenAPI document (issue 39, point 2): what every operation states, read from the
//! document the service serves (`pantowatch::api::openapi`). The snapshot and the role table
//! are in `cases` (`openapi_snapshot`, `every_route_every_role`).

use pantowatch::api::doc::BEARER;
use pantowatch::api::error::PROBLEM_JSON;

/// Every answer of every operation has its description (OpenAPI 3.1 requires one; the
/// validator's 39 errors were responses without), and every refusal is a problem document.
/// Each `/v1` operation names its scheme and least role and answers 401, 429 and 5xx; 403
/// exactly when the role is above reader; 404 when the path names something; the body's
/// 413/415/422 when it takes one.
pub fn every_operation_states_its_security_and_every_answer() {
    let doc = serde_json::to_value(pantowatch::api::openapi()).expect("doc");
    let shared = &doc["components"]["responses"];
    let mut operations = 0;
    for (path, item) in doc["paths"].as_object().expect("paths") {
        for (method, op) in item.as_object().expect("item") {
            operations += 1;
            let what = format!("{method} {path}");
            let responses = op["responses"].as_object().expect("responses");
            for (status, r) in responses {
                let r = match r["$ref"].as_str() {
                    Some(to) => &shared[to.rsplit('/').next().expect("name")],
                    None => r,
                };
                let text = r["description"].as_str().unwrap_or("");
                assert!(!text.is_empty(), "{what} {status}: no description");
                if status.starts_with('4') || status.starts_with('5') {
                    assert_eq!(
                        r["content"][PROBLEM_JSON]["schema"]["$ref"],
                        "#/components/schemas/Problem",
                        "{what} {status}"
                    );
                }
            }
            let has = |s: &str| responses.contains_key(s);
            for s in ["414", "500", "503"] {
                assert!(has(s), "{what}: no {s}");
            }
            if !path.starts_with("/v1/") {
                assert!(op.get("security").is_none(), "{what} needs no key");
                continue;
            }
            let role = op["security"][0][BEARER][0].as_str().unwrap_or("");
            assert!(
                ["reader", "writer", "admin"].contains(&role),
                "{what}: role {role:?}"
            );
            for s in ["401", "429"] {
                assert!(has(s), "{what}: no {s}");
            }
            assert_eq!(has("403"), role != "reader", "{what}: 403 and role {role}");
            if path.contains('{') {
                assert!(has("400") && has("404"), "{what}: no 400/404");
            }
            if op.get("requestBody").is_some() {
                for s in ["400", "413", "415", "422", "507"] {
                    assert!(has(s), "{what}: no {s}");
                }
            }
        }
    }
    assert_eq!(operations, 30);
}
