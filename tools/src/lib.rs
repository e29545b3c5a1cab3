//! pantowatch-tools: the command-line tools that are not the service — the benchmark suite
//! (`bench`) and the load generator (`load`). They use the service library (`pantowatch`) and
//! the physics (`pantowatch-models`); the service library knows nothing of them.

pub mod bench;
pub mod load;
