//! Where `topspin bench latency` puts its threads. `shared`: nowhere in
//! particular, no SCHED_FIFO (today's behaviour, the figures of a shared
//! 2-core machine). `dedicated`: the budgets of DESIGN §9 are for dedicated
//! cores, so each hot thread of the daemon (RSI, estimator, ingest), the
//! mock KR C4 and the simulated tracker get a physical core of their own
//! with SCHED_FIFO, the RSI loop and the estimator busy-poll (as `topspin
//! doctor` advises), and telemetry and the `--load` hogs share the cores
//! left over (the main thread, which only waits, stays unpinned: the
//! threads it spawns inherit its CPU set and pin themselves inside it).
//!
//! [`plan`] is the pure choice of cores from the CPUs this process may use
//! and their topology; [`read_topology`] is its thin I/O shell over sysfs.

use std::collections::BTreeMap;
use std::fmt;

use serde::Serialize;

/// How the bench lays out its threads.
#[derive(Copy, Clone, Debug, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Layout {
    /// Any core, normal scheduling, the wait strategies given.
    Shared,
    /// A physical core and SCHED_FIFO for each of the five; busy-poll.
    Dedicated,
}

/// One CPU the process may use and the physical core it belongs to
/// (`(package, core)`: SMT siblings share it).
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct Cpu {
    pub id: usize,
    pub core: (usize, usize),
}

/// The threads that get a physical core of their own, hottest first: the
/// hottest takes the highest-numbered core (CPU 0 takes most interrupts
/// and housekeeping by default; `isolcpus=` is usually set at the top).
pub const DEDICATED: [&str; 5] = ["rsi", "estimator", "ingest", "mock_krc", "tracker"];

/// Physical cores [`Layout::Dedicated`] needs: one per [`DEDICATED`]
/// thread and one for the rest.
pub const CORES_NEEDED: usize = DEDICATED.len() + 1;

/// SCHED_FIFO priorities of the mock KR C4 and the tracker (each alone on
/// its core; the daemon's are its own: RSI 80, ingest 70, estimator 60).
pub const HELPER_PRIORITY: i32 = 50;

/// The CPU of each thread.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct Placement {
    pub rsi: usize,
    pub estimator: usize,
    pub ingest: usize,
    pub mock_krc: usize,
    pub tracker: usize,
    /// Telemetry and hogs: the cores no dedicated thread has.
    pub rest: Vec<usize>,
    /// SMT siblings of the dedicated CPUs, left idle so that they do not
    /// share a core's execution units with a hot thread.
    pub idle: Vec<usize>,
}

impl Placement {
    /// `(thread, cpu)` in [`DEDICATED`] order.
    pub fn dedicated(&self) -> [(&'static str, usize); 5] {
        [
            ("rsi", self.rsi),
            ("estimator", self.estimator),
            ("ingest", self.ingest),
            ("mock_krc", self.mock_krc),
            ("tracker", self.tracker),
        ]
    }
}

/// Too few physical cores for [`Layout::Dedicated`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TooFewCores {
    pub physical: usize,
    pub cpus: Vec<usize>,
}

impl fmt::Display for TooFewCores {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "--layout dedicated needs {CORES_NEEDED} physical cores (RSI, estimator, ingest, mock KR C4, tracker, one for the rest); \
             this process may use {} CPU(s) ({}) on {} physical core(s)",
            self.cpus.len(),
            cpu_list(&self.cpus),
            self.physical
        )
    }
}

/// `0-3,6`: a CPU list as the kernel writes one.
pub fn cpu_list(cpus: &[usize]) -> String {
    let mut out: Vec<String> = Vec::new();
    let mut i = 0;
    while i < cpus.len() {
        let mut j = i;
        while j + 1 < cpus.len() && cpus[j + 1] == cpus[j] + 1 {
            j += 1;
        }
        out.push(if j > i { format!("{}-{}", cpus[i], cpus[j]) } else { cpus[i].to_string() });
        i = j + 1;
    }
    if out.is_empty() { "none".to_owned() } else { out.join(",") }
}

/// Chooses the cores: the physical cores ordered by their lowest CPU; the
/// last five go to [`DEDICATED`] (hottest last), each on its lowest CPU
/// with its siblings idle; the CPUs of the others are the rest.
pub fn plan(cpus: &[Cpu]) -> Result<Placement, TooFewCores> {
    let mut by_core: BTreeMap<(usize, usize), Vec<usize>> = BTreeMap::new();
    for c in cpus {
        let v = by_core.entry(c.core).or_default();
        if !v.contains(&c.id) {
            v.push(c.id);
        }
    }
    let mut cores: Vec<Vec<usize>> = by_core.into_values().collect();
    for c in &mut cores {
        c.sort_unstable();
    }
    cores.sort_unstable_by_key(|c| c[0]);
    if cores.len() < CORES_NEEDED {
        let mut all: Vec<usize> = cores.concat();
        all.sort_unstable();
        return Err(TooFewCores { physical: cores.len(), cpus: all });
    }
    let split = cores.len() - DEDICATED.len();
    let (rest, hot) = cores.split_at(split);
    // hot[4] is the highest core: the RSI loop's.
    let pick = |k: usize| hot[DEDICATED.len() - 1 - k][0];
    let mut rest: Vec<usize> = rest.concat();
    rest.sort_unstable();
    let mut idle: Vec<usize> = hot.iter().flat_map(|c| c[1..].iter().copied()).collect();
    idle.sort_unstable();
    Ok(Placement { rsi: pick(0), estimator: pick(1), ingest: pick(2), mock_krc: pick(3), tracker: pick(4), rest, idle })
}

/// The allowed CPUs with their physical cores from
/// `/sys/devices/system/cpu/cpuN/topology/{physical_package_id,core_id}`;
/// a CPU whose topology cannot be read counts as a core of its own.
pub fn read_topology(allowed: &[usize]) -> Vec<Cpu> {
    let read = |cpu: usize, file: &str| -> Option<usize> {
        std::fs::read_to_string(format!("/sys/devices/system/cpu/cpu{cpu}/topology/{file}")).ok()?.trim().parse().ok()
    };
    allowed
        .iter()
        .map(|&id| {
            let core = match (read(id, "physical_package_id"), read(id, "core_id")) {
                (Some(p), Some(c)) => (p, c),
                _ => (usize::MAX, id),
            };
            Cpu { id, core }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn no_smt(ids: &[usize]) -> Vec<Cpu> {
        ids.iter().map(|&id| Cpu { id, core: (0, id) }).collect()
    }

    #[test]
    fn two_cores_are_refused_naming_what_was_found() {
        let e = plan(&no_smt(&[0, 1])).unwrap_err();
        assert_eq!(e, TooFewCores { physical: 2, cpus: vec![0, 1] });
        assert_eq!(
            e.to_string(),
            "--layout dedicated needs 6 physical cores (RSI, estimator, ingest, mock KR C4, tracker, one for the rest); \
             this process may use 2 CPU(s) (0-1) on 2 physical core(s)"
        );
        assert_eq!(plan(&no_smt(&[0, 1, 2, 3, 4])).unwrap_err().physical, 5);
        assert_eq!(plan(&[]).unwrap_err(), TooFewCores { physical: 0, cpus: vec![] });
    }

    #[test]
    fn six_cores_give_the_hot_threads_the_top_five() {
        let p = plan(&no_smt(&[0, 1, 2, 3, 4, 5])).unwrap();
        assert_eq!(
            p,
            Placement { rsi: 5, estimator: 4, ingest: 3, mock_krc: 2, tracker: 1, rest: vec![0], idle: vec![] }
        );
        assert_eq!(p.dedicated()[0], ("rsi", 5));
    }

    #[test]
    fn more_cores_go_to_the_rest() {
        let p = plan(&no_smt(&[7, 0, 3, 1, 6, 2, 5, 4])).unwrap();
        assert_eq!(
            p,
            Placement { rsi: 7, estimator: 6, ingest: 5, mock_krc: 4, tracker: 3, rest: vec![0, 1, 2], idle: vec![] }
        );
    }

    #[test]
    fn smt_siblings_of_the_hot_cores_stay_idle() {
        // 6 cores, 12 threads, Linux's numbering: CPU n and n + 6 share core n.
        let cpus: Vec<Cpu> = (0..12).map(|id| Cpu { id, core: (0, id % 6) }).collect();
        let p = plan(&cpus).unwrap();
        assert_eq!(
            p,
            Placement {
                rsi: 5,
                estimator: 4,
                ingest: 3,
                mock_krc: 2,
                tracker: 1,
                rest: vec![0, 6],
                idle: vec![7, 8, 9, 10, 11]
            }
        );
    }

    #[test]
    fn four_cores_with_eight_threads_are_not_six_cores() {
        let cpus: Vec<Cpu> = (0..8).map(|id| Cpu { id, core: (0, id % 4) }).collect();
        let e = plan(&cpus).unwrap_err();
        assert_eq!(e, TooFewCores { physical: 4, cpus: (0..8).collect() });
        assert!(e.to_string().contains("8 CPU(s) (0-7) on 4 physical core(s)"), "{e}");
    }

    #[test]
    fn a_narrowed_set_on_two_sockets() {
        // taskset -c 2,3,5,8-11 on two packages whose core ids restart at 0.
        let cpus = [
            Cpu { id: 2, core: (0, 2) },
            Cpu { id: 3, core: (0, 3) },
            Cpu { id: 5, core: (0, 5) },
            Cpu { id: 8, core: (1, 0) },
            Cpu { id: 9, core: (1, 1) },
            Cpu { id: 10, core: (1, 2) },
            Cpu { id: 11, core: (1, 3) },
        ];
        let p = plan(&cpus).unwrap();
        assert_eq!(
            p,
            Placement { rsi: 11, estimator: 10, ingest: 9, mock_krc: 8, tracker: 5, rest: vec![2, 3], idle: vec![] }
        );
        // A CPU listed twice is one CPU.
        let mut twice = cpus.to_vec();
        twice.push(cpus[0]);
        assert_eq!(plan(&twice).unwrap(), p);
    }

    #[test]
    fn cpu_lists_read_as_the_kernel_writes_them() {
        assert_eq!(cpu_list(&[0, 1]), "0-1");
        assert_eq!(cpu_list(&[0, 2, 3, 4, 7]), "0,2-4,7");
        assert_eq!(cpu_list(&[5]), "5");
        assert_eq!(cpu_list(&[]), "none");
    }
}
