//! What a benchmark ran on: CPU model, cores, load, rustc and the git commit — printed above
//! every suite table, since the figures mean nothing without it.

use std::process::Command;

use serde::Serialize;

/// The machine line of a run.
#[derive(Debug, Clone, Serialize)]
pub struct Machine {
    /// `model name` of /proc/cpuinfo (`n/a` elsewhere).
    pub cpu: String,
    /// Cores this process may use (`available_parallelism`).
    pub cores: usize,
    /// 1-minute load average at the start (/proc/loadavg): other work on the cores.
    pub load_1m: Option<f64>,
    /// `rustc --version` of the toolchain on PATH (assumed to be the one that built this binary).
    pub rustc: String,
    /// `git rev-parse --short HEAD` of the working directory, `-dirty` with local changes.
    pub commit: String,
    /// Release or debug build of this binary.
    pub profile: &'static str,
}

fn output(cmd: &str, args: &[&str]) -> Option<String> {
    let out = Command::new(cmd).args(args).output().ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_owned())
}

impl Machine {
    /// Reads the machine now.
    pub fn detect() -> Machine {
        let cpu = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|s| {
                s.lines()
                    .find(|l| l.starts_with("model name"))
                    .and_then(|l| l.split_once(':'))
                    .map(|(_, v)| v.trim().to_owned())
            })
            .unwrap_or_else(|| "n/a".into());
        let load_1m = std::fs::read_to_string("/proc/loadavg")
            .ok()
            .and_then(|s| s.split_whitespace().next()?.parse().ok());
        let commit = match output("git", &["rev-parse", "--short", "HEAD"]) {
            Some(c) => {
                let dirty = output("git", &["status", "--porcelain", "--untracked-files=no"])
                    .is_some_and(|s| !s.is_empty());
                if dirty { format!("{c}-dirty") } else { c }
            }
            None => "n/a".into(),
        };
        Machine {
            cpu,
            cores: std::thread::available_parallelism().map_or(1, usize::from),
            load_1m,
            rustc: output("rustc", &["--version"]).unwrap_or_else(|| "n/a".into()),
            commit,
            profile: if cfg!(debug_assertions) {
                "debug"
            } else {
                "release"
            },
        }
    }

    /// One line for the table's header.
    pub fn line(&self) -> String {
        let load = self
            .load_1m
            .map_or_else(|| "n/a".into(), |l| format!("{l:.1}"));
        format!(
            "Machine: {} × {} cores (load {load} at start); {}; commit {}; {} build",
            self.cpu, self.cores, self.rustc, self.commit, self.profile
        )
    }
}
