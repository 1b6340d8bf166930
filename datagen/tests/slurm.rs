//! `deploy/slurm/datagen.sbatch`, unchanged, on a real Slurm: a private single-node cluster
//! (its own `munged`, `slurmctld` and `slurmd` on localhost, free ports, a temporary folder;
//! stopped when the test ends) runs the job file as a 3-task array into one output folder. The
//! dataset passes `datagen check` and is byte-identical to one `datagen render` process. Faults:
//! an array task cancelled (`scancel`) mid-render, then the same array range resubmitted as the
//! job file's header says: the finished jobs are skipped, the dataset is again byte-identical,
//! and the killed task left no partial file behind.
//!
//! Needs Debian's `slurm-wlm` and `munge` (`.ci/run` installs them) and root (the daemons'
//! users); without them the test says so and passes, as there is no scheduler to test against.

mod common;

use common::{assert_same, fresh_dir, snapshot, test_config};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_datagen");

/// How long an array may take before the test fails (the whole test takes ≈ 1 minute).
const ARRAY_TIMEOUT: Duration = Duration::from_secs(120);

/// The Slurm and MUNGE programs the test drives, where the packages put them.
struct Tools {
    munged: PathBuf,
    slurmctld: PathBuf,
    slurmd: PathBuf,
    sbatch: PathBuf,
    squeue: PathBuf,
    scancel: PathBuf,
}

impl Tools {
    /// The tools, or why the test cannot run here.
    fn find() -> Result<Self, String> {
        let find = |name: &str| -> Result<PathBuf, String> {
            let path = std::env::var_os("PATH").unwrap_or_default();
            std::env::split_paths(&path)
                .chain(["/usr/sbin", "/usr/bin", "/sbin"].map(PathBuf::from))
                .map(|dir| dir.join(name))
                .find(|p| p.is_file())
                .ok_or_else(|| {
                    format!("`{name}` not found (Debian: apt-get install slurm-wlm munge)")
                })
        };
        let uid = Command::new("id")
            .arg("-u")
            .output()
            .map_err(|e| format!("id -u: {e}"))?;
        if String::from_utf8_lossy(&uid.stdout).trim() != "0" {
            return Err("the Slurm daemons of the test need root".into());
        }
        Ok(Self {
            munged: find("munged")?,
            slurmctld: find("slurmctld")?,
            slurmd: find("slurmd")?,
            sbatch: find("sbatch")?,
            squeue: find("squeue")?,
            scancel: find("scancel")?,
        })
    }
}

/// A free TCP port on localhost (bound once, then released for the daemon).
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free local port")
}

/// A running private cluster; its daemons are stopped when it is dropped.
struct Cluster {
    tools: Tools,
    dir: PathBuf,
    conf: PathBuf,
}

impl Cluster {
    /// Starts MUNGE, the controller and one node of 16 CPUs (the job file asks for 16 per task;
    /// `config_overrides` lets the node claim them on a smaller machine, so the three tasks run
    /// one after another) under `dir`.
    fn start(tools: Tools, dir: &Path) -> Self {
        for sub in ["state", "spool", "log"] {
            std::fs::create_dir_all(dir.join(sub)).unwrap();
        }
        // MUNGE: a private key and socket, so no system daemon is needed or disturbed.
        let key = dir.join("munge.key");
        let bytes: Vec<u8> = (0..1024u32)
            .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
            .collect();
        std::fs::write(&key, bytes).unwrap();
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o400)).unwrap();
        let socket = dir.join("munge.sock");
        let status = Command::new(&tools.munged)
            .arg("--force")
            .arg(format!("--socket={}", socket.display()))
            .arg(format!("--key-file={}", key.display()))
            .arg(format!("--pid-file={}", dir.join("munged.pid").display()))
            .arg(format!(
                "--log-file={}",
                dir.join("log/munged.log").display()
            ))
            .arg(format!("--seed-file={}", dir.join("munged.seed").display()))
            .status()
            .expect("munged starts");
        assert!(status.success(), "munged failed to start");
        let conf = dir.join("slurm.conf");
        let p = |name: &str| dir.join(name).display().to_string();
        std::fs::write(
            &conf,
            format!(
                "ClusterName=sppmtest\n\
                 SlurmctldHost=localhost\n\
                 SlurmUser=root\n\
                 SlurmdUser=root\n\
                 AuthType=auth/munge\n\
                 AuthInfo=socket={socket}\n\
                 ProctrackType=proctrack/linuxproc\n\
                 TaskPlugin=task/none\n\
                 SelectType=select/cons_tres\n\
                 SelectTypeParameters=CR_Core\n\
                 SchedulerType=sched/builtin\n\
                 JobAcctGatherType=jobacct_gather/none\n\
                 AccountingStorageType=accounting_storage/none\n\
                 MpiDefault=none\n\
                 ReturnToService=2\n\
                 SlurmdParameters=config_overrides\n\
                 StateSaveLocation={state}\n\
                 SlurmdSpoolDir={spool}\n\
                 SlurmctldPidFile={ctld_pid}\n\
                 SlurmdPidFile={d_pid}\n\
                 SlurmctldLogFile={ctld_log}\n\
                 SlurmdLogFile={d_log}\n\
                 SlurmctldPort={ctld_port}\n\
                 SlurmdPort={d_port}\n\
                 NodeName=localhost CPUs=16 RealMemory=16384 State=UNKNOWN\n\
                 PartitionName=test Nodes=localhost Default=YES MaxTime=INFINITE State=UP\n",
                socket = socket.display(),
                state = p("state"),
                spool = p("spool"),
                ctld_pid = p("slurmctld.pid"),
                d_pid = p("slurmd.pid"),
                ctld_log = p("log/slurmctld.log"),
                d_log = p("log/slurmd.log"),
                ctld_port = free_port(),
                d_port = free_port(),
            ),
        )
        .unwrap();
        let cluster = Self {
            tools,
            dir: dir.to_owned(),
            conf,
        };
        // `-i`: ignore any saved state (the folder is new anyway).
        let ctld = cluster.command(&cluster.tools.slurmctld).arg("-i").status();
        assert!(ctld.is_ok_and(|s| s.success()), "slurmctld failed to start");
        let d = cluster
            .command(&cluster.tools.slurmd)
            .args(["-N", "localhost"])
            .status();
        assert!(d.is_ok_and(|s| s.success()), "slurmd failed to start");
        cluster
    }

    /// A command of the cluster's (its config in `SLURM_CONF`), without the array variables of
    /// an enclosing job.
    fn command(&self, program: &Path) -> Command {
        let mut cmd = Command::new(program);
        cmd.env("SLURM_CONF", &self.conf);
        for var in [
            "SLURM_ARRAY_TASK_ID",
            "SLURM_ARRAY_TASK_COUNT",
            "SLURM_ARRAY_TASK_MIN",
            "SLURM_JOB_ID",
        ] {
            cmd.env_remove(var);
        }
        cmd
    }

    /// Submits the job file unchanged as the array `range` rendering `config` into `out`;
    /// returns the array's job id. Logs go to `logs`.
    fn submit(&self, range: &str, config: &Path, out: &Path, logs: &Path) -> String {
        std::fs::create_dir_all(logs).unwrap();
        let job_file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy/slurm/datagen.sbatch");
        let output = self
            .command(&self.tools.sbatch)
            .env("DATAGEN", BIN)
            .arg("--parsable")
            .arg(format!("--chdir={}", logs.display()))
            .arg(format!("--array={range}"))
            .arg(&job_file)
            .arg(config)
            .arg(out)
            .output()
            .expect("sbatch runs");
        assert!(
            output.status.success(),
            "sbatch failed: {}",
            String::from_utf8_lossy(&output.stderr)
        );
        String::from_utf8_lossy(&output.stdout).trim().to_owned()
    }

    /// The array's tasks still queued or running, as `(task id, state)`.
    fn tasks(&self, job: &str) -> Vec<(String, String)> {
        let output = self
            .command(&self.tools.squeue)
            .args(["-h", "-r", "-o", "%K %T", "-j", job])
            .output()
            .expect("squeue runs");
        String::from_utf8_lossy(&output.stdout)
            .lines()
            .filter_map(|l| l.split_once(' '))
            .map(|(a, b)| (a.to_owned(), b.to_owned()))
            .collect()
    }

    /// Waits until the array `job` has left the queue.
    fn wait(&self, job: &str) {
        let start = Instant::now();
        while !self.tasks(job).is_empty() {
            assert!(
                start.elapsed() < ARRAY_TIMEOUT,
                "array {job} still queued after {ARRAY_TIMEOUT:?}: {:?}\nslurmctld log:\n{}",
                self.tasks(job),
                std::fs::read_to_string(self.dir.join("log/slurmctld.log")).unwrap_or_default()
            );
            std::thread::sleep(Duration::from_millis(200));
        }
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        for pid in ["slurmd.pid", "slurmctld.pid", "munged.pid"] {
            if let Ok(pid) = std::fs::read_to_string(self.dir.join(pid)) {
                let _ = Command::new("kill").arg(pid.trim()).status();
            }
        }
    }
}

/// What each task's log says of its shard: `(rendered, already done)` job counts, by task.
fn shard_reports(logs: &Path, job: &str) -> Vec<(usize, usize)> {
    (0..3)
        .map(|task| {
            let log = logs.join(format!("datagen-{job}_{task}.log"));
            let text = std::fs::read_to_string(&log).unwrap_or_default();
            let line = text
                .lines()
                .find(|l| l.starts_with(&format!("shard {task}/3:")))
                .unwrap_or_else(|| panic!("{}: no shard report in\n{text}", log.display()));
            let count = |after: &str| -> usize {
                let words: Vec<&str> = line.split_whitespace().collect();
                let k = words
                    .iter()
                    .position(|w| *w == after)
                    .expect("report shape");
                words[k - 1].parse().expect("a count")
            };
            (count("jobs"), count("already"))
        })
        .collect()
}

/// Files under `dir` whose names mark an unfinished write or an unfinished run.
fn leftovers(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap().flatten() {
        let path = entry.path();
        let name = entry.file_name().to_string_lossy().into_owned();
        if path.is_dir() {
            out.extend(leftovers(&path));
        } else if name.contains(".tmp") || name.ends_with(".state") {
            out.push(path);
        }
    }
    out
}

/// The finished (not hidden) EXR files under `dir`.
fn visible_exrs(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap().flatten() {
        let path = entry.path();
        let name = entry.file_name().to_string_lossy().into_owned();
        if path.is_dir() {
            out.extend(visible_exrs(&path));
        } else if name.ends_with(".exr") && !name.starts_with('.') {
            out.push(path);
        }
    }
    out
}

/// `datagen render` of `config` in one process into `out`.
fn render_in_one_process(config: &Path, out: &Path) {
    let status = Command::new(BIN)
        .args(["render", "--quiet", "--config"])
        .arg(config)
        .arg("--out")
        .arg(out)
        .env_remove("SLURM_ARRAY_TASK_ID")
        .env_remove("SLURM_ARRAY_TASK_COUNT")
        .env_remove("JOB_COMPLETION_INDEX")
        .status()
        .unwrap();
    assert!(status.success());
}

fn check(out: &Path) {
    let output = Command::new(BIN).arg("check").arg(out).output().unwrap();
    assert!(
        output.status.success(),
        "datagen check {}: {}{}",
        out.display(),
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
}

#[test]
fn the_job_file_runs_on_slurm_and_resubmission_finishes_a_cancelled_array() {
    let tools = match Tools::find() {
        Ok(tools) => tools,
        Err(why) => {
            eprintln!("SKIPPED: no Slurm to run deploy/slurm/datagen.sbatch on: {why}");
            return;
        }
    };
    let dir = fresh_dir("slurm");
    let cluster = Cluster::start(tools, &dir.join("cluster"));

    // The tiny config as a 3-task array into one folder.
    let tiny = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/datagen/tiny.toml");
    let out = dir.join("array");
    let job = cluster.submit("0-2", &tiny, &out, &dir.join("logs"));
    cluster.wait(&job);
    check(&out);
    let single = dir.join("single");
    render_in_one_process(&tiny, &single);
    assert_same(&snapshot(&single), &snapshot(&out));
    assert!(leftovers(&out).is_empty(), "{:?}", leftovers(&out));

    // A config whose reference runs last a few seconds, so that a task can be cancelled
    // mid-render.
    let slow = dir.join("slow.toml");
    let mut config = test_config(24, &[2, 4], 1, 2000);
    config.render.reference_photons_per_pass = 2000;
    std::fs::write(&slow, toml::to_string(&config).unwrap()).unwrap();
    let out = dir.join("faults");
    let logs = dir.join("fault-logs");
    let first = cluster.submit("0-2", &slow, &out, &logs);
    // Task 1 is cancelled a second into its render (its shard takes several).
    let log = logs.join(format!("datagen-{first}_1.log"));
    let start = Instant::now();
    loop {
        let running = cluster
            .tasks(&first)
            .iter()
            .any(|(task, state)| task == "1" && state == "RUNNING");
        let started = std::fs::read_to_string(&log).is_ok_and(|t| t.contains("task 1 of 3"));
        if running && started {
            break;
        }
        assert!(start.elapsed() < ARRAY_TIMEOUT, "task 1 never started");
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_secs(1));
    let cancelled = cluster
        .command(&cluster.tools.scancel)
        .arg(format!("{first}_1"))
        .status()
        .unwrap();
    assert!(cancelled.success());
    cluster.wait(&first);
    // Whatever the killed task had finished is whole: every visible EXR reads back.
    let exrs = visible_exrs(&out);
    assert!(!exrs.is_empty());
    for exr in &exrs {
        let name = exr.display().to_string();
        let whole = if name.contains("/references/") {
            bundle::read_rgb_exr_image(exr).map(|_| ())
        } else {
            bundle::read_bundle(exr).map(|_| ())
        };
        assert!(whole.is_ok(), "{name}: {whole:?}");
    }
    assert!(
        !out.join("manifest.json").exists(),
        "a dataset with a cancelled shard must not be complete"
    );
    // Resubmitting the same range renders only what is missing.
    let second = cluster.submit("0-2", &slow, &out, &logs);
    cluster.wait(&second);
    let reports = shard_reports(&logs, &second);
    assert!(
        reports[0].0 == 0 && reports[2].0 == 0 && reports[0].1 > 0 && reports[2].1 > 0,
        "the shards that finished must be skipped: {reports:?}"
    );
    assert!(
        reports[1].0 > 0,
        "the cancelled shard must render again: {reports:?}"
    );
    check(&out);
    assert!(
        leftovers(&out).is_empty(),
        "partial files left: {:?}",
        leftovers(&out)
    );
    let single = dir.join("slow-single");
    render_in_one_process(&slow, &single);
    assert_same(&snapshot(&single), &snapshot(&out));
    drop(cluster);
    let _ = std::fs::remove_dir_all(&dir);
}
