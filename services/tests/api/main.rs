//! HTTP tests of the service: the real server on 127.0.0.1:0 against a fresh SQLite file and,
//! with the same cases, a fresh PostgreSQL database (`PANTOWATCH_TEST_PG_URL`, default
//! `postgres://postgres@127.0.0.1:5432/postgres`; unreachable PostgreSQL fails the tests).
//!
//! `PANTOWATCH_BLESS=1 cargo test -p pantowatch --test api openapi` rewrites the committed
//! OpenAPI snapshot `services/openapi.json` from the served document.

mod alerts;
mod browser;
mod cases;
mod corpus;
mod fleet_prior;
mod gauge;
mod harness;
mod lift;
mod openapi;
mod plan;
mod pooled_rig;
mod quadrangle;
mod security;
mod static_force;

use harness::Backend;

macro_rules! suite {
    ($($case:ident),+ $(,)?) => {
        mod sqlite {
            $(
                #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
                async fn $case() {
                    crate::cases::$case(crate::Backend::Sqlite).await;
                }
            )+
        }
        mod postgres {
            $(
                #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
                async fn $case() {
                    crate::cases::$case(crate::Backend::Postgres).await;
                }
            )+
        }
    };
}

suite!(
    upload_fit_status_history_fleet,
    idempotent_upload_and_conflict,
    csv_upload_and_samples_round_trip,
    every_route_every_role,
    rejections_answer_problems_and_store_nothing,
    stopped_between_upload_and_fit_fits_once,
    dead_worker_job_is_reclaimed_after_its_lease,
    lift_trace_is_fitted_with_every_joint,
    bad_lift_inputs_are_refused_naming_the_sample,
    recent_lifts_are_pooled,
    a_designed_lift_is_accepted_and_fitted,
    a_model_error_raises_no_wear_alarm,
    a_sensor_delay_is_a_sensor_finding_not_a_joint_alarm,
    keys_created_and_revoked_over_http,
    readiness_and_metrics,
    alert_lifecycle_over_http,
    an_uninformative_lift_leaves_a_workshop_alarm_standing,
    webhooks_signed_retried_and_logged,
    corpus_uploads_are_refused_and_store_nothing,
    edge_dates_never_break_their_vehicle,
    hostile_requests_answer_problems_naming_their_field,
    a_release_is_found_or_stated_and_reported,
    a_disturbed_release_is_left_out_and_said,
    static_force_is_predicted_and_judged_against_the_limits,
    a_named_spring_rate_moves_the_static_force_prediction,
    a_gauge_measurement_is_stored_refused_and_drawn,
    a_gauge_record_pools_with_the_next_lift,
    a_gauge_zero_or_spring_rate_is_a_finding_not_a_joint_alarm,
    recordings_of_one_rig_are_fitted_pooled,
    evidence_plan_and_test_due_over_http,
    the_kept_fleet_plan_is_the_plan_from_scratch,
    a_fleet_prior_is_learned_versioned_recorded_and_refitted,
    a_gauge_fit_and_a_pooled_lift_follow_the_fleet_prior,
);

/// The web pages in headless Chromium against a small demo fleet (SQLite).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn web_pages_in_headless_chromium() {
    browser::web_pages_in_headless_chromium().await;
}

#[test]
fn openapi_every_operation_states_its_security_and_every_answer() {
    openapi::every_operation_states_its_security_and_every_answer();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn openapi_snapshot() {
    cases::openapi_snapshot(Backend::Sqlite).await;
}
