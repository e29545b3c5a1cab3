//! The web pages in headless Chromium (`/usr/bin/chromium`, or `PANTOWATCH_CHROMIUM`) against a
//! small demo fleet uploaded through the API: `--dump-dom` and `--screenshot` subprocess calls.
//!
//! The signed-in browser goes through a loopback proxy that adds the session cookie (headless
//! Chromium takes no cookie on its command line). The proxy also serves `/__post?to=PATH&k=v…`,
//! a page of its own whose script submits a form of those fields to PATH, so the browser itself
//! posts (a wrong key to `/login`, a reader's acknowledge) and renders the answer. Sign-in and
//! the writer's acknowledge are also plain HTTP form posts. Screenshots land in
//! `target/screenshots/`.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use axum::body::Bytes;
use axum::extract::State;
use axum::http::{Method as AxMethod, StatusCode as AxStatus, Uri};
use axum::response::{IntoResponse, Response};
use pantowatch::cli::demo::fleet;
use pantowatch::cli::simulate::simulate_doc;
use reqwest::StatusCode;
use serde_json::Value;
use tokio::sync::Semaphore;

use crate::harness::*;

fn chromium() -> String {
    std::env::var("PANTOWATCH_CHROMIUM").unwrap_or_else(|_| "/usr/bin/chromium".into())
}

fn shots_dir() -> PathBuf {
    let d: PathBuf = [env!("CARGO_MANIFEST_DIR"), "..", "target", "screenshots"]
        .iter()
        .collect();
    std::fs::create_dir_all(&d).expect("target/screenshots");
    d
}

/// Runs headless Chromium with `args` then `url`; returns stdout.
async fn chrome(profile: &Path, args: &[String], url: &str) -> String {
    let out = tokio::time::timeout(
        Duration::from_secs(90),
        tokio::process::Command::new(chromium())
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-dev-shm-usage",
                "--no-first-run",
                "--hide-scrollbars",
                "--window-size=1280,1800",
            ])
            .arg(format!("--user-data-dir={}", profile.display()))
            .args(args)
            .arg(url)
            .kill_on_drop(true)
            .output(),
    )
    .await
    .expect("chromium within 90 s")
    .unwrap_or_else(|e| panic!("{} could not run (CI installs it): {e}", chromium()));
    assert!(
        out.status.success(),
        "chromium failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

async fn dom(profile: &Path, url: &str) -> String {
    chrome(profile, &["--dump-dom".into()], url).await
}

async fn screenshot(profile: &Path, url: &str, name: &str) {
    let path = shots_dir().join(name);
    let _ = std::fs::remove_file(&path);
    chrome(profile, &[format!("--screenshot={}", path.display())], url).await;
    let size = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
    assert!(size > 10_000, "screenshot {name}: {size} bytes");
}

struct Proxy {
    target: String,
    cookie: String,
    client: reqwest::Client,
}

/// The proxy's form driver: a page that posts `fields` to `to` as soon as it loads.
fn form_driver(query: &str) -> Response {
    let q: Vec<(String, String)> = serde_urlencoded::from_str(query).unwrap_or_default();
    let to = q.iter().find(|(k, _)| k == "to").map_or("/", |(_, v)| v);
    let page = maud::html! {
        (maud::DOCTYPE)
        html {
            body {
                form method="post" action=(to) {
                    @for (k, v) in q.iter().filter(|(k, _)| k != "to") {
                        input type="hidden" name=(k) value=(v);
                    }
                }
                script { "document.forms[0].submit()" }
            }
        }
    };
    page.into_response()
}

/// Forwards a request to the app with the session cookie (and the headers a page request
/// carries: what it accepts, what its body is).
async fn forward(
    State(p): State<Arc<Proxy>>,
    method: AxMethod,
    uri: Uri,
    headers: axum::http::HeaderMap,
    body: Bytes,
) -> Response {
    if uri.path() == "/__post" {
        return form_driver(uri.query().unwrap_or(""));
    }
    let path = uri.path_and_query().map_or("/", |p| p.as_str());
    let m = reqwest::Method::from_bytes(method.as_str().as_bytes()).unwrap_or(reqwest::Method::GET);
    let mut req = p
        .client
        .request(m, format!("{}{path}", p.target))
        .header("cookie", &p.cookie)
        .body(body);
    for h in ["accept", "content-type"] {
        if let Some(v) = headers.get(h).and_then(|v| v.to_str().ok()) {
            req = req.header(h, v);
        }
    }
    match req.send().await {
        Ok(r) => {
            let status = AxStatus::from_u16(r.status().as_u16()).unwrap_or(AxStatus::BAD_GATEWAY);
            let ct = r
                .headers()
                .get("content-type")
                .and_then(|v| v.to_str().ok())
                .unwrap_or("text/html")
                .to_owned();
            let loc = r
                .headers()
                .get("location")
                .and_then(|v| v.to_str().ok())
                .map(str::to_owned);
            let bytes = r.bytes().await.unwrap_or_default();
            let mut resp = (status, [("content-type", ct)], bytes).into_response();
            if let Some(l) = loc.and_then(|l| l.parse().ok()) {
                resp.headers_mut().insert("location", l);
            }
            resp
        }
        Err(e) => (AxStatus::BAD_GATEWAY, e.to_string()).into_response(),
    }
}

/// A proxy to the app that signs every request in with `cookie`; its base URL.
async fn start_proxy(app: &TestApp, client: &reqwest::Client, cookie: &str) -> String {
    let proxy = Arc::new(Proxy {
        target: app.url(""),
        cookie: cookie.to_owned(),
        client: client.clone(),
    });
    let router = axum::Router::new().fallback(forward).with_state(proxy);
    let l = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let base = format!("http://{}", l.local_addr().expect("addr"));
    tokio::spawn(async move {
        let _ = axum::serve(l, router).await;
    });
    base
}

/// Signs in with `key` over plain HTTP; the session cookie (`name=value`).
async fn sign_in(app: &TestApp, client: &reqwest::Client, key: &str) -> String {
    let r = client
        .post(app.url("/login"))
        .header("content-type", "application/x-www-form-urlencoded")
        .body(serde_urlencoded::to_string([("key", key)]).expect("form"))
        .send()
        .await
        .expect("login");
    assert_eq!(r.status(), StatusCode::SEE_OTHER);
    let set_cookie = r
        .headers()
        .get("set-cookie")
        .and_then(|v| v.to_str().ok())
        .expect("set-cookie")
        .to_owned();
    assert!(
        set_cookie.contains("HttpOnly")
            && set_cookie.contains("Secure")
            && set_cookie.contains("SameSite=Strict"),
        "{set_cookie}"
    );
    set_cookie.split(';').next().expect("cookie").to_owned()
}

/// The value of the first `attr="…"` in `html`.
fn first_attr<'a>(html: &'a str, attr: &str) -> Option<&'a str> {
    let start = html.find(&format!("{attr}=\""))? + attr.len() + 2;
    let end = html[start..].find('"')? + start;
    Some(&html[start..end])
}

/// Each joint section of a pantograph page: (joint, its HTML).
fn joint_sections(dom: &str) -> Vec<(String, &str)> {
    dom.split("<section id=\"joint-")
        .skip(1)
        .filter_map(|s| {
            let (joint, rest) = s.split_once('"')?;
            Some((
                joint.to_owned(),
                rest.split("</section>").next().unwrap_or(rest),
            ))
        })
        .collect()
}

/// The charts of a joint section, by parameter: each plotted point's (status class, trace).
fn chart_points(section: &str) -> Vec<(String, Vec<(String, String)>)> {
    section
        .split("data-param=\"")
        .skip(1)
        .filter_map(|c| {
            let (param, rest) = c.split_once('"')?;
            let points = rest
                .split("<g class=\"pt ")
                .skip(1)
                .filter_map(|g| {
                    let (class, after) = g.split_once('"')?;
                    Some((
                        class.to_owned(),
                        first_attr(after, "data-trace")?.to_owned(),
                    ))
                })
                .collect();
            Some((param.to_owned(), points))
        })
        .collect()
}

/// A page rendered as the site's HTML (its heading and, signed in, its navigation), not the
/// API's problem JSON.
fn assert_site_page(dom: &str, heading: &str, signed_in: bool) {
    assert!(
        dom.contains(&format!("<h1>{heading}</h1>")),
        "{heading}: {dom}"
    );
    assert!(
        dom.contains("<header><strong>pantowatch</strong>"),
        "site header: {dom}"
    );
    assert!(
        !dom.contains("\"type\":") && !dom.contains("/problems/") && !dom.contains("&lt;"),
        "no problem JSON, no escaped markup: {dom}"
    );
    assert_eq!(
        dom.contains("Sign out") && dom.contains("href=\"/fleet\""),
        signed_in,
        "navigation when signed in: {dom}"
    );
}

fn status_rank(s: &str) -> u8 {
    match s {
        "alarm" => 3,
        "watch" => 2,
        "ok" => 1,
        _ => 0,
    }
}

/// A small demo fleet through `POST /v1/traces`; waits until every fit is done.
async fn seed_demo_fleet(app: &TestApp, vehicles: usize) -> usize {
    let plan = fleet::plan(vehicles).expect("plan");
    let n = plan.len();
    let permits = Arc::new(Semaphore::new(4));
    let mut set = tokio::task::JoinSet::new();
    for test in plan {
        let permit = permits.clone().acquire_owned().await.expect("permit");
        let body = tokio::task::spawn_blocking(move || {
            let doc = simulate_doc(&test.args).expect("simulate");
            serde_json::to_vec(&doc.to_value()).expect("json")
        });
        let (client, url, key) = (
            app.client.clone(),
            app.url("/v1/traces"),
            app.keys.writer.clone(),
        );
        set.spawn(async move {
            let body = body.await.expect("synthesis");
            let r = client
                .post(url)
                .bearer_auth(key)
                .header("content-type", "application/json")
                .body(body)
                .send()
                .await
                .expect("upload");
            assert_eq!(r.status(), StatusCode::ACCEPTED);
            drop(permit);
        });
    }
    while let Some(r) = set.join_next().await {
        r.expect("upload task");
    }
    let t0 = Instant::now();
    loop {
        let c = app.store.job_counts().await.expect("jobs");
        if c.queued + c.running == 0 {
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(300),
            "fits not done: {c:?}"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    n
}

pub async fn web_pages_in_headless_chromium() {
    let t0 = Instant::now();
    let app = spawn_app(Backend::Sqlite).await;
    // Four vehicles: eight pantographs, three of them wearing (one towards alarm).
    let n = seed_demo_fleet(&app, 4).await;
    let seeded = t0.elapsed();
    let profile = tempfile::tempdir().expect("profile dir");

    // Not signed in: every page but the sign-in sends you to it.
    let plain = reqwest::Client::builder()
        .redirect(reqwest::redirect::Policy::none())
        .timeout(Duration::from_secs(30))
        .no_proxy()
        .build()
        .expect("client");
    for p in ["/fleet", "/alerts", "/pantographs/160EC-0101", "/traces/x"] {
        let r = plain.get(app.url(p)).send().await.expect("GET");
        assert_eq!(r.status(), StatusCode::SEE_OTHER, "{p}");
        assert_eq!(
            r.headers().get("location").and_then(|v| v.to_str().ok()),
            Some("/")
        );
    }
    let login = dom(profile.path(), &app.url("/")).await;
    assert!(login.contains("name=\"key\""), "{login}");
    screenshot(profile.path(), &app.url("/"), "01-login.png").await;

    // A wrong key, posted by the browser from a form: the sign-in page again with the reason,
    // answered 401 (the status over plain HTTP).
    let anon = start_proxy(&app, &plain, "pw_session=none").await;
    let failed = dom(
        profile.path(),
        &format!("{anon}/__post?to=/login&key=pw_not_a_key"),
    )
    .await;
    assert_site_page(&failed, "Sign in", false);
    assert!(
        failed.contains("<title>Sign-in failed · pantowatch</title>")
            && failed.contains("role=\"alert\">Unknown or revoked API key.</p>")
            && failed.contains("name=\"key\""),
        "{failed}"
    );
    let r = plain
        .post(app.url("/login"))
        .header("content-type", "application/x-www-form-urlencoded")
        .body(serde_urlencoded::to_string([("key", "pw_not_a_key")]).expect("form"))
        .send()
        .await
        .expect("login");
    assert_eq!(r.status(), StatusCode::UNAUTHORIZED);
    assert!(
        r.headers()["content-type"]
            .to_str()
            .is_ok_and(|c| c.starts_with("text/html"))
    );
    // Sign in (a form post) → the session cookie.
    let cookie = sign_in(&app, &plain, &app.keys.writer).await;
    let base = start_proxy(&app, &plain, &cookie).await;

    // Fleet: the worst pantograph first.
    let fleet_dom = dom(profile.path(), &format!("{base}/fleet")).await;
    let first = first_attr(&fleet_dom, "data-serial")
        .expect("a fleet row")
        .to_owned();
    let (s, health) = app.get_json("/v1/fleet/health?limit=500").await;
    assert_eq!(s, StatusCode::OK);
    let rank = |s: &Value| match s.as_str() {
        Some("alarm") => 3,
        Some("watch") => 2,
        Some("ok") => 1,
        _ => 0,
    };
    let rows = health["rows"].as_array().expect("rows");
    let worst = rows
        .iter()
        .map(|r| rank(&r["worst_status"]))
        .max()
        .expect("rows");
    assert!(
        worst >= 2,
        "the demo fleet has joints at watch or alarm: {health}"
    );
    let first_row = rows
        .iter()
        .find(|r| r["serial"] == first.as_str())
        .expect("first row");
    assert_eq!(
        rank(&first_row["worst_status"]),
        worst,
        "worst first: {first} {health}"
    );
    screenshot(profile.path(), &format!("{base}/fleet"), "02-fleet.png").await;
    // Issue 15: alerts and fleet health come from one state and agree on every pantograph —
    // each joint at watch or alarm has a live alert of that severity, and each live alert
    // raised on a status names a joint at that status.
    let (s, live) = app.get_json("/v1/alerts?state=live").await;
    assert_eq!(s, StatusCode::OK);
    let live = live["alerts"].as_array().cloned().unwrap_or_default();
    for r in rows {
        for j in r["not_ok"].as_array().into_iter().flatten() {
            if matches!(j["status"].as_str(), Some("watch" | "alarm")) {
                assert!(
                    live.iter().any(|a| a["serial"] == r["serial"]
                        && a["joint"] == j["joint"]
                        && a["severity"] == j["status"]),
                    "fleet health {r} has no live alert for {j}"
                );
            }
        }
    }
    for a in &live {
        if a["reason"]
            .as_str()
            .is_some_and(|r| r.starts_with("status"))
        {
            let row = rows
                .iter()
                .find(|r| r["serial"] == a["serial"])
                .expect("alert's row");
            assert!(
                row["not_ok"]
                    .as_array()
                    .into_iter()
                    .flatten()
                    .any(|j| j["joint"] == a["joint"] && j["status"] == a["severity"]),
                "live alert {a} disagrees with fleet health {row}"
            );
        }
    }

    // The worst pantograph's page: charts with text alternatives, a link to a trace.
    let pdom = dom(profile.path(), &format!("{base}/pantographs/{first}")).await;
    assert!(pdom.contains("<svg") && pdom.contains("<desc>") && pdom.contains("<title>"));
    assert!(pdom.contains("Table 4 baseline"), "chart descriptions");
    screenshot(
        profile.path(),
        &format!("{base}/pantographs/{first}"),
        "03-pantograph.png",
    )
    .await;
    // Issue 37: what each joint rests on — a row per joint of the type with its evidence's age
    // as a bar (J2' is never swung: never measured) — and the ranked workshop tests; the fleet
    // table's oldest-evidence column. At the demo year's end (its tests run 2025-05 to 2026-04).
    let at = "at=2026-05-01T00:00:00Z";
    let edom = dom(profile.path(), &format!("{base}/pantographs/{first}?{at}")).await;
    let table = edom
        .split("id=\"evidence-table\"")
        .nth(1)
        .and_then(|t| t.split("</table>").next())
        .expect("evidence table");
    assert_eq!(table.matches("<tr data-joint=").count(), 9, "{table}");
    for j in ["J1", "J2", "J3", "J4", "J5", "J6", "J7", "J8"] {
        assert!(
            table.contains(&format!("data-joint=\"{j}\"")),
            "{j}: {table}"
        );
    }
    assert_eq!(table.matches("class=\"age\"").count(), 9, "{table}");
    assert!(table.contains("never measured"), "J2' never swung: {table}");
    assert!(table.contains(" d</span>"), "ages in days: {table}");
    let plan = edom
        .split("id=\"plan-table\"")
        .nth(1)
        .and_then(|t| t.split("</table>").next())
        .expect("plan table");
    assert!(plan.contains("swing J"), "{plan}");
    screenshot(
        profile.path(),
        &format!("{base}/pantographs/{first}?{at}"),
        "03b-evidence.png",
    )
    .await;
    let fdom = dom(profile.path(), &format!("{base}/fleet?{at}")).await;
    assert!(fdom.contains("oldest evidence"), "fleet column");
    assert_eq!(
        fdom.matches("class=\"oldest\"").count(),
        8,
        "a cell per pantograph: {fdom}"
    );
    // A gauged pantograph (every fourth, `demo::fleet::gauged`): its static-force chart draws the
    // latest force-gauge test's readings, a marker per reading and a class per branch (issue 20).
    let gauged = "160EC-0102";
    let gdom = dom(profile.path(), &format!("{base}/pantographs/{gauged}")).await;
    let gsection = gdom
        .split("id=\"static-force\"")
        .nth(1)
        .unwrap_or_else(|| panic!("{gauged}: a static force section: {gdom}"));
    assert_eq!(
        (
            gsection.matches("class=\"gauge-raise\"").count(),
            gsection.matches("class=\"gauge-lower\"").count()
        ),
        (15, 14),
        "{gauged}: {gsection}"
    );
    assert!(
        gsection.contains("raising, gauge (15 readings)"),
        "{gsection}"
    );
    // Each joint's badge and its charts' latest points carry one status (issue 18): the badge's
    // class is the worst of the classes of each parameter's latest plotted point (the joint's
    // state is each parameter from the latest test that informed it, the joint at the worst).
    // And a chart plots exactly the tests that informed its parameter: a lift that cannot see a
    // joint's parameter (reported at baseline with the prior's interval) draws no point for it.
    let sections = joint_sections(&pdom);
    assert!(sections.len() >= 8, "every joint has a section: {pdom}");
    let (mut not_ok_checked, mut uninformed_lifts) = (0, 0);
    for (joint, section) in &sections {
        let badge = first_attr(section, "class")
            .and_then(|c| c.strip_prefix("badge "))
            .unwrap_or_else(|| panic!("{joint}: a status badge: {section}"));
        let charts = chart_points(section);
        assert_eq!(charts.len(), 2, "{joint}: a viscous and a dry chart");
        let latest = charts
            .iter()
            .filter_map(|(_, pts)| pts.last().map(|(class, _)| class.as_str()))
            .max_by_key(|c| status_rank(c))
            .unwrap_or("unknown");
        assert_eq!(badge, latest, "{joint}: badge vs latest points: {section}");
        if badge != "ok" && badge != "unknown" {
            not_ok_checked += 1;
        }
        let path = format!("/v1/pantographs/{first}/joints/{joint}/history");
        let (s, history) = app.get_json(&path).await;
        if joint.contains('+') {
            // A combination a lift reports (`J1+J3`) has no history route of its own.
            assert_eq!(s, StatusCode::BAD_REQUEST, "{path}: {history}");
            continue;
        }
        assert_eq!(s, StatusCode::OK, "{path}: {history}");
        let history = history["points"].as_array().cloned().unwrap_or_default();
        for (param, pts) in &charts {
            let informed: Vec<&str> = history
                .iter()
                .filter(|p| {
                    let own = &p[format!("{param}_status").as_str()];
                    let status = own.as_str().or(p["status"].as_str()).unwrap_or("unknown");
                    !p[param.as_str()].is_null()
                        && p[format!("{param}_informed").as_str()]
                            .as_bool()
                            .unwrap_or(p["identifiable"] == true)
                        && status != "unknown"
                })
                .filter_map(|p| p["trace_id"].as_str())
                .collect();
            let drawn: Vec<&str> = pts.iter().map(|(_, t)| t.as_str()).collect();
            assert_eq!(
                drawn, informed,
                "{joint} {param}: points drawn vs tests that informed it"
            );
            uninformed_lifts += history
                .iter()
                .filter(|p| {
                    p["trace_id"].as_str().is_some_and(|t| t.ends_with("-lift"))
                        && !p[param.as_str()].is_null()
                        && p[format!("{param}_informed").as_str()] == false
                })
                .count();
        }
    }
    assert!(
        not_ok_checked > 0,
        "a joint at watch or alarm was checked: {pdom}"
    );
    assert!(
        uninformed_lifts > 0,
        "some lift left a parameter uninformed (and drew no point for it)"
    );
    // A single-joint trace (its page draws measured vs model; a lift trace's page shows the
    // joints and the finding).
    let trace = pdom
        .match_indices("href=\"/traces/")
        .filter_map(|(i, _)| first_attr(&pdom[i..], "href"))
        .find(|h| !h.ends_with("-lift"))
        .expect("a single-joint trace link")
        .to_owned();
    let tdom = dom(profile.path(), &format!("{base}{trace}")).await;
    assert!(
        tdom.contains("Measured vs model") && tdom.contains("id=\"finding\""),
        "{tdom}"
    );
    screenshot(profile.path(), &format!("{base}{trace}"), "04-trace.png").await;
    // A lift's page names the test, the assembly and the pantograph, and no internal error.
    let (s, j3) = app
        .get_json(&format!("/v1/pantographs/{first}/joints/J3/history"))
        .await;
    assert_eq!(s, StatusCode::OK);
    let lift = j3["points"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|p| p["trace_id"].as_str())
        .find(|t| t.ends_with("-lift"))
        .expect("a lift of the worst pantograph")
        .to_owned();
    let ldom = dom(profile.path(), &format!("{base}/traces/{lift}")).await;
    assert!(
        ldom.contains(&format!(
            "<p id=\"tested\">lift test of the whole pantograph on pantograph \
             <a href=\"/pantographs/{first}\">{first}</a> (vehicle EN57-"
        )),
        "{ldom}"
    );
    assert!(ldom.contains(&format!("<h1>Trace {lift}</h1>")), "{ldom}");
    // Its measured and model H, from the curve stored with the fit (issue 19, point 4).
    assert!(ldom.contains("Measured vs model"), "{ldom}");
    for internal in [
        "No model curve",
        "not a single-joint",
        "id=\"no-curve\"",
        "pantograph —",
    ] {
        assert!(!ldom.contains(internal), "{internal}: {ldom}");
    }
    screenshot(
        profile.path(),
        &format!("{base}/traces/{lift}"),
        "07-lift-trace.png",
    )
    .await;

    // Unknown pages, signed in: the site's 404 page with its navigation; a malformed path or
    // query: its 400 page.
    for (path, heading, detail) in [
        (
            "/pantographs/160EC-9999",
            "Not found",
            "no pantograph `160EC-9999`",
        ),
        (
            "/traces/no-such-trace",
            "Not found",
            "no trace `no-such-trace`",
        ),
        ("/nowhere", "Not found", "no route GET /nowhere"),
        ("/traces/%FF", "Bad request", ""),
        (
            "/alerts?done=1&done=2",
            "Bad request",
            "duplicate field `done`",
        ),
    ] {
        let d = dom(profile.path(), &format!("{base}{path}")).await;
        assert_site_page(&d, heading, true);
        assert!(d.contains(detail), "{path}: {d}");
        let r = plain
            .get(app.url(path))
            .header("cookie", &cookie)
            .header("accept", "text/html")
            .send()
            .await
            .expect("GET");
        let status = if heading == "Not found" { 404 } else { 400 };
        assert_eq!(r.status().as_u16(), status, "{path}");
    }
    screenshot(
        profile.path(),
        &format!("{base}/pantographs/160EC-9999"),
        "08-not-found.png",
    )
    .await;

    // Alerts: the demo leaves some open; acknowledge one on the page, see it over REST.
    let (s, open) = app.get_json("/v1/alerts?state=open").await;
    assert_eq!(s, StatusCode::OK);
    let open = open["alerts"].as_array().cloned().unwrap_or_default();
    assert!(!open.is_empty(), "alerts open after the demo fleet");
    let adom = dom(profile.path(), &format!("{base}/alerts")).await;
    let id = open[0]["id"].as_i64().expect("id");
    // A reader posting the acknowledge form (the page offers none to a reader): the site's 403
    // page with the reader's navigation, and the alert stays open.
    let reader = sign_in(&app, &plain, &app.keys.reader).await;
    let rbase = start_proxy(&app, &plain, &reader).await;
    let denied = dom(
        profile.path(),
        &format!("{rbase}/__post?to=/alerts/{id}/acknowledge&note=reader"),
    )
    .await;
    assert_site_page(&denied, "Forbidden", true);
    assert!(
        denied.contains("acknowledging needs a writer key") && denied.contains("reader key"),
        "{denied}"
    );
    let (s, a) = app.get_json(&format!("/v1/alerts/{id}")).await;
    assert_eq!(s, StatusCode::OK);
    assert_eq!(a["alert"]["state"], "open", "{a}");
    assert!(
        adom.contains(&format!("action=\"/alerts/{id}/acknowledge\"")),
        "ack form"
    );
    screenshot(profile.path(), &format!("{base}/alerts"), "05-alerts.png").await;
    let r = plain
        .post(app.url(&format!("/alerts/{id}/acknowledge")))
        .header("cookie", &cookie)
        .header("content-type", "application/x-www-form-urlencoded")
        .body(serde_urlencoded::to_string([("note", "seen in the depot")]).expect("form"))
        .send()
        .await
        .expect("acknowledge form");
    assert_eq!(r.status(), StatusCode::SEE_OTHER);
    let (s, a) = app.get_json(&format!("/v1/alerts/{id}")).await;
    assert_eq!(s, StatusCode::OK);
    assert_eq!(a["alert"]["state"], "acknowledged", "{a}");
    assert!(
        a["alert"]["acknowledged_by"]
            .as_str()
            .is_some_and(|w| w.contains("(key "))
    );
    assert_eq!(
        a["events"]
            .as_array()
            .and_then(|e| e.last())
            .map(|e| e["note"].clone()),
        Some(Value::from("seen in the depot"))
    );
    let adom = dom(profile.path(), &format!("{base}/alerts?done={id}")).await;
    assert!(
        adom.contains(&format!("id=\"alert-{id}\" data-state=\"acknowledged\"")),
        "{adom}"
    );
    screenshot(
        profile.path(),
        &format!("{base}/alerts?done={id}"),
        "06-acknowledged.png",
    )
    .await;
    eprintln!(
        "browser test: {n} demo traces seeded and fitted in {:.1} s, pages checked in {:.1} s",
        seeded.as_secs_f64(),
        (t0.elapsed() - seeded).as_secs_f64()
    );
    app.stop().await;
}
