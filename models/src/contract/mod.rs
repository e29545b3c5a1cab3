//! What a fit means to the service: the contract's fit result, a test described as data, drift
//! status against Table 4, and wear trends across tests.

pub mod drift;
pub mod evidence;
pub mod plan;
pub mod report;
pub mod testspec;
pub mod trend;
pub mod withhold;
