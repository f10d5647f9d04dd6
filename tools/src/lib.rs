//! What the experiment programs in `src/bin/` share.

/// The machine, in one line: CPU model, cores, load and memory.
pub fn machine() -> String {
    let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let model = cpuinfo
        .lines()
        .find_map(|l| l.strip_prefix("model name").and_then(|r| r.split_once(':')).map(|(_, m)| m.trim().to_string()))
        .unwrap_or_else(|| "unknown CPU".into());
    let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let load = load.split_whitespace().take(3).collect::<Vec<_>>().join(" ");
    let mem = std::fs::read_to_string("/proc/meminfo").unwrap_or_default();
    let mem_gib = mem
        .lines()
        .find_map(|l| l.strip_prefix("MemTotal:"))
        .and_then(|r| r.split_whitespace().next()?.parse::<f64>().ok())
        .map_or(String::from("?"), |kib| format!("{:.0}", kib / 1024.0 / 1024.0));
    format!("Machine: {model}, {cores} cores (nproc), {mem_gib} GiB memory, load average {load} at start.")
}

/// η of the hierarchy's sweeps (`hierarchy-table`, `hierarchy-chart`): issue 18's, and the
/// default η.
pub const HIERARCHY_ETAS: [f64; 6] = [0.0, 1e-4, 1e-3, 4e-3, 1e-2, 3e-2];

pub mod args;
pub mod corpus;
pub mod experiments;
pub mod walk_loads;
/// CPU time this process has used (all its threads), to the nanosecond: on a machine shared with
/// other work, a single-threaded measurement's CPU time is far steadier than its wall clock.
pub fn process_cpu_time() -> std::time::Duration {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid timespec for clock_gettime to write.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) };
    if rc != 0 {
        return std::time::Duration::ZERO;
    }
    std::time::Duration::new(ts.tv_sec as u64, ts.tv_nsec as u32)
}
