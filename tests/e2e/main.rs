//! End-to-end tests: identification of the shared example traces (made by an independent
//! simulator) against their truth, interval coverage on synthetic traces, the measured trace.

mod ambiguity;
mod architecture;
mod architecture_doc;
mod body_uncertainty;
mod coverage;
mod driven;
mod examples;
mod lift;
mod quadrangle;
mod residual;
