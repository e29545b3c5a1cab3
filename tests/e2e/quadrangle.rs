//! The lower-quadrangle swing end to end (issue 5, point 3): `pantowatch simulate --kind
//! quadrangle_swing` writes a document with J1's dry friction drifted ×3 (truth 0.069, Table 4
//! 0.023), the fit through `fitting::fit_document` recovers it within its interval and flags J1
//! alone, and `pantowatch fit --plot` on the file writes the α measured-vs-fitted SVG.

use clap::Parser;
use pantowatch::cli::fit::FitArgs;
use pantowatch::cli::simulate::{SimulateArgs, simulate_doc};
use pantowatch_models::drift::{DriftThresholds, Status};

#[derive(Parser)]
struct Sim {
    #[command(flatten)]
    args: SimulateArgs,
}

const J1_DRY_TRUTH: f64 = 0.023 * 3.0;

#[test]
fn simulated_j1_drift_swing_is_recovered_and_flagged_alone() {
    let args = Sim::try_parse_from([
        "simulate",
        "--kind",
        "quadrangle_swing",
        "--scale-joint",
        "J1:dry=3",
        "--duration",
        "12",
        "--fs",
        "250",
        "--offset",
        "0.4",
        "--beta-offset=-0.3",
        "--seed",
        "8",
        "--trace-id",
        "swing-j1",
    ])
    .unwrap()
    .args;
    let doc = simulate_doc(&args).unwrap();
    let r = pantowatch::fitting::fit_document(&doc, &DriftThresholds::default()).unwrap();
    let names: Vec<&str> = r.joints.iter().map(|j| j.joint.as_str()).collect();
    assert_eq!(names, ["J1", "J2", "J2'", "J3"]);
    for j in &r.joints {
        eprintln!(
            "{:>3} {:?} identifiable {} viscous {:.4} [{:.4}, {:.4}] dry {:.4} [{:.4}, {:.4}]",
            j.joint,
            j.status,
            j.identifiable,
            j.viscous.value,
            j.viscous.ci95[0],
            j.viscous.ci95[1],
            j.dry.value,
            j.dry.ci95[0],
            j.dry.ci95[1]
        );
        if j.joint == "J1" {
            assert!(j.dry.identifiable, "J1 dry informed");
            assert!(matches!(j.status, Status::Watch | Status::Alarm));
            assert!(j.dry.ci95[0] <= J1_DRY_TRUTH && J1_DRY_TRUTH <= j.dry.ci95[1]);
        } else {
            assert!(
                matches!(j.status, Status::Ok | Status::Unknown),
                "{}",
                j.joint
            );
        }
        for p in [&j.viscous, &j.dry] {
            if !p.identifiable {
                assert_eq!((p.status, Some(p.value)), (Status::Unknown, p.baseline));
            }
        }
    }
    assert_eq!(r.rmse.unit, "deg");
    assert!(r.rmse.value < 0.06, "{}", r.rmse.value);
    // The α sensor zero the document was made with (0.4°) is inside the fitted one's interval.
    let ci = r.fit.sensor_offset_ci95.expect("zero interval");
    assert!(ci[0] <= 0.4 && 0.4 <= ci[1], "{ci:?}");

    // `pantowatch fit --plot` on the file.
    let dir = std::env::temp_dir().join(format!("pantowatch-e2e-swing-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (file, svg) = (dir.join("swing.json"), dir.join("swing.svg"));
    std::fs::write(&file, serde_json::to_vec(&doc.to_value()).unwrap()).unwrap();
    pantowatch::cli::fit::run(
        FitArgs {
            trace: file,
            more: Vec::new(),
            pooled: false,
            json: true,
            plot: Some(svg.clone()),
            report: None,
        },
        &DriftThresholds::default(),
    )
    .unwrap();
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.starts_with("<svg") && text.contains("alpha measured vs fitted"));
    std::fs::remove_dir_all(&dir).unwrap();
}
