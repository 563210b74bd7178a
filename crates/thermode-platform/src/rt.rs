//! What the operating system grants a real-time process: real-time scheduling for the control-loop thread
//! (`SCHED_FIFO`), memory locked in RAM (`mlockall`, so no page fault stalls a tick), a CPU of its own for the loop
//! (the other threads, whose network traffic raises soft interrupts on the CPU that sends it, kept off it), and the
//! open-files limit the network side sizes its connection cap from. Each is asked for, never assumed: the answer ([`Realtime`]) is
//! published, and a refusal leaves the process as it was.
//!
//! Linux only (`libc`); elsewhere every request is refused with "not supported on this platform".
#![allow(unsafe_code)]

/// What [`request_realtime`] obtained.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Realtime {
    /// The calling thread runs under `SCHED_FIFO` at this priority (1 = lowest, 99 = highest); `None` if refused.
    pub fifo_priority: Option<i32>,
    /// Why real-time scheduling was not obtained (or not asked for).
    pub scheduling_error: Option<String>,
    /// The process's memory is locked in RAM (current and future pages).
    pub memory_locked: bool,
    /// Why memory was not locked (or not asked for).
    pub memory_error: Option<String>,
    /// The CPU the thread is pinned to, when it has one to itself (see [`split_cpus`]).
    pub cpu: Option<usize>,
}

impl Realtime {
    /// Nothing asked for: normal scheduling, memory not locked, both for `reason`.
    pub fn not_requested(reason: &str) -> Self {
        Realtime {
            fifo_priority: None,
            scheduling_error: Some(reason.to_string()),
            memory_locked: false,
            memory_error: Some(reason.to_string()),
            cpu: None,
        }
    }

    /// One line for a banner: `SCHED_FIFO 50, memory locked` or the refusals.
    pub fn describe(&self) -> String {
        let scheduling = match (self.fifo_priority, &self.scheduling_error) {
            (Some(p), _) => format!("SCHED_FIFO priority {p}"),
            (None, Some(e)) => format!("normal scheduling ({e})"),
            (None, None) => "normal scheduling".to_string(),
        };
        let memory = match (self.memory_locked, &self.memory_error) {
            (true, _) => "memory locked".to_string(),
            (false, Some(e)) => format!("memory not locked ({e})"),
            (false, None) => "memory not locked".to_string(),
        };
        match self.cpu {
            Some(cpu) => format!("{scheduling}, {memory}, alone on CPU {cpu}"),
            None => format!("{scheduling}, {memory}"),
        }
    }
}

/// Default `SCHED_FIFO` priority of the control loop: 50, the middle of 1..=99 (above every normal thread; on
/// PREEMPT_RT kernels the threaded interrupt handlers run at 50 too).
pub const DEFAULT_FIFO_PRIORITY: i32 = 50;

/// Asks for `SCHED_FIFO` at `priority` (1..=99) for the calling thread, then (if `lock_memory`) for every current
/// and future page of the process to be locked in RAM. Memory is locked only when the memory-lock limit is
/// unlimited or the process may exceed it (root): a limited `MCL_FUTURE` lock would make later allocations fail.
pub fn request_realtime(priority: i32, lock_memory: bool) -> Realtime {
    let (fifo_priority, scheduling_error) = match set_fifo(priority) {
        Ok(()) => (Some(priority), None),
        Err(e) => (None, Some(e)),
    };
    let (memory_locked, memory_error) = if lock_memory {
        match lock_all_memory() {
            Ok(()) => (true, None),
            Err(e) => (false, Some(e)),
        }
    } else {
        (false, Some("not requested".to_string()))
    };
    Realtime {
        fifo_priority,
        scheduling_error,
        memory_locked,
        memory_error,
        cpu: None,
    }
}

/// The CPUs the process may run on: the last one for the real-time loop and the others for every other thread, when
/// there are at least two; `None` otherwise (or where affinity is not supported).
pub fn split_cpus() -> Option<(usize, Vec<usize>)> {
    let mut cpus = allowed_cpus();
    let loop_cpu = cpus.pop()?;
    (!cpus.is_empty()).then_some((loop_cpu, cpus))
}

/// Pins the calling thread to `cpus` (an error when refused or unsupported).
pub fn pin_current_thread(cpus: &[usize]) -> Result<(), String> {
    set_affinity(cpus)
}

#[cfg(target_os = "linux")]
fn allowed_cpus() -> Vec<usize> {
    // SAFETY: an all-zero cpu_set_t is a valid empty set.
    let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
    // SAFETY: pid 0 is the calling thread; the size is that of the set we own, which the call fills.
    let rc = unsafe { libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set) };
    if rc != 0 {
        return Vec::new();
    }
    (0..libc::CPU_SETSIZE as usize)
        // SAFETY: `cpu` is below CPU_SETSIZE, inside the set.
        .filter(|&cpu| unsafe { libc::CPU_ISSET(cpu, &set) })
        .collect()
}

#[cfg(target_os = "linux")]
fn set_affinity(cpus: &[usize]) -> Result<(), String> {
    // SAFETY: an all-zero cpu_set_t is a valid empty set.
    let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
    for &cpu in cpus.iter().filter(|&&cpu| cpu < libc::CPU_SETSIZE as usize) {
        // SAFETY: `cpu` is below CPU_SETSIZE, inside the set we own.
        unsafe { libc::CPU_SET(cpu, &mut set) };
    }
    // SAFETY: pid 0 is the calling thread; `set` is a valid set of the size given, read only.
    let rc = unsafe { libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) };
    if rc == 0 {
        Ok(())
    } else {
        Err(format!("CPU affinity refused: {}", std::io::Error::last_os_error()))
    }
}

/// The soft limit of open files (`RLIMIT_NOFILE`) of the process, if known.
pub fn open_files_limit() -> Option<u64> {
    #[cfg(target_os = "linux")]
    {
        let mut limit = libc::rlimit {
            rlim_cur: 0,
            rlim_max: 0,
        };
        // SAFETY: getrlimit writes one rlimit into the struct we own and reads nothing else.
        let rc = unsafe { libc::getrlimit(libc::RLIMIT_NOFILE, &mut limit) };
        (rc == 0).then_some(limit.rlim_cur)
    }
    #[cfg(not(target_os = "linux"))]
    {
        None
    }
}

#[cfg(target_os = "linux")]
fn set_fifo(priority: i32) -> Result<(), String> {
    if !(1..=99).contains(&priority) {
        return Err(format!("priority {priority} outside 1 to 99"));
    }
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: pid 0 is the calling thread; `param` is a valid sched_param that outlives the call.
    let rc = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) };
    if rc == 0 {
        Ok(())
    } else {
        Err(format!("SCHED_FIFO refused: {}", std::io::Error::last_os_error()))
    }
}

#[cfg(target_os = "linux")]
fn lock_all_memory() -> Result<(), String> {
    let mut limit = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit writes one rlimit into the struct we own.
    let rc = unsafe { libc::getrlimit(libc::RLIMIT_MEMLOCK, &mut limit) };
    // SAFETY: geteuid has no preconditions.
    let root = unsafe { libc::geteuid() } == 0;
    if rc != 0 {
        return Err(format!(
            "cannot read the memory-lock limit: {}",
            std::io::Error::last_os_error()
        ));
    }
    if limit.rlim_cur != libc::RLIM_INFINITY && !root {
        return Err(format!(
            "the memory-lock limit is {} bytes (ulimit -l); locking future pages could make allocations fail",
            limit.rlim_cur
        ));
    }
    // SAFETY: mlockall takes flags only.
    let rc = unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) };
    if rc == 0 {
        Ok(())
    } else {
        Err(format!("mlockall refused: {}", std::io::Error::last_os_error()))
    }
}

#[cfg(not(target_os = "linux"))]
fn set_fifo(_priority: i32) -> Result<(), String> {
    Err("not supported on this platform".into())
}

#[cfg(not(target_os = "linux"))]
fn lock_all_memory() -> Result<(), String> {
    Err("not supported on this platform".into())
}

#[cfg(not(target_os = "linux"))]
fn allowed_cpus() -> Vec<usize> {
    Vec::new()
}

#[cfg(not(target_os = "linux"))]
fn set_affinity(_cpus: &[usize]) -> Result<(), String> {
    Err("not supported on this platform".into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bad_priority_is_refused_and_nothing_requested_says_so() {
        let rt = request_realtime(0, false);
        assert_eq!(rt.fifo_priority, None);
        assert!(rt
            .scheduling_error
            .is_some_and(|e| e.contains("1 to 99") || e.contains("platform")));
        assert!(!rt.memory_locked);
        assert!(Realtime::not_requested("off")
            .describe()
            .contains("normal scheduling (off)"));
        assert!(open_files_limit().is_none_or(|n| n > 0));
    }

    #[test]
    fn the_loop_cpu_is_apart_from_the_others() {
        if let Some((loop_cpu, others)) = split_cpus() {
            assert!(
                !others.is_empty() && !others.contains(&loop_cpu),
                "{loop_cpu} vs {others:?}"
            );
            assert!(allowed_cpus().contains(&loop_cpu));
        }
    }
}
