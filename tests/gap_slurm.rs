//! The Slurm recipe of `docs/gap.md` (`docs/gap/slurm/submit.sh`) run as written on a real
//! one-node Slurm on localhost: the calibration job, an array of two shards that read it,
//! and the merge chained after them. The merged table must equal an unsharded run of the same
//! campaign case by case (wall times aside), every shard's log must show a line per finished
//! case although no terminal is attached, and every daemon the test started (munged,
//! slurmctld, slurmd) is stopped when it ends, pass or fail.
//!
//! The cluster lives in the test's temporary directory (its own munge key and socket, state,
//! spool, logs and ports), so it neither needs nor touches a system Slurm, and a second run
//! right after the first starts from nothing.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use eyebot_hil::gap::bench::{self, CaseResult, Part};
use eyebot_test_support::process::{ChildGuard, free_tcp_port};
use eyebot_test_support::{TempDir, require_tool, wait_for, workspace_root};

/// The campaign: two library effects and the nulls, one case each (three cases).
const CAMPAIGN: [&str; 8] = [
    "--source",
    "simulator",
    "--cases",
    "1",
    "--seed",
    "5150",
    "--effects",
    "water_current,depth_offset",
];
const SHARDS: usize = 2;

/// The daemons of a one-node cluster, stopped (and any job left cancelled) on drop.
struct Cluster {
    conf: PathBuf,
    jobcomp: PathBuf,
    // Declared in the order they stop: the node, the controller, then munge.
    slurmd: Option<ChildGuard>,
    slurmctld: Option<ChildGuard>,
    munged: Option<ChildGuard>,
    jobs: Vec<String>,
}

impl Cluster {
    fn start(dir: &Path) -> Self {
        let munged = require_tool("munged", "munge");
        let mungekey = require_tool("mungekey", "munge");
        let slurmctld = require_tool("slurmctld", "slurmctld");
        let slurmd = require_tool("slurmd", "slurmd");
        require_tool("sbatch", "slurm-client");
        require_tool("sinfo", "slurm-client");

        let munge_dir = dir.join("munge");
        for d in ["munge", "state", "spool", "log"] {
            std::fs::create_dir_all(dir.join(d)).expect("cluster directories");
        }
        let key = munge_dir.join("munge.key");
        let status = Command::new(mungekey)
            .arg("--create")
            .arg(format!("--keyfile={}", key.display()))
            .status()
            .expect("run mungekey");
        assert!(status.success(), "mungekey --create: {status}");
        let socket = munge_dir.join("socket");
        let mut munge = Command::new(munged);
        munge
            .args(["--foreground", "--force"])
            .arg(format!("--socket={}", socket.display()))
            .arg(format!("--key-file={}", key.display()))
            .arg(format!("--pid-file={}", munge_dir.join("pid").display()))
            .arg(format!("--log-file={}", munge_dir.join("log").display()))
            .arg(format!("--seed-file={}", munge_dir.join("seed").display()))
            .stdout(Stdio::null())
            .stderr(Stdio::null());
        let mut cluster = Cluster {
            conf: dir.join("slurm.conf"),
            jobcomp: dir.join("log/jobcomp.txt"),
            slurmd: None,
            slurmctld: None,
            munged: Some(ChildGuard::spawn("munged", &mut munge)),
            jobs: Vec::new(),
        };
        wait_for("munged's socket", Duration::from_secs(10), || {
            socket.exists().then_some(())
        });

        // The node as this machine describes itself, under the name `localhost`.
        let described = Command::new(&slurmd)
            .arg("-C")
            .output()
            .expect("run slurmd -C");
        let described = String::from_utf8_lossy(&described.stdout);
        let node = described
            .lines()
            .find(|l| l.starts_with("NodeName="))
            .unwrap_or_else(|| panic!("slurmd -C printed no NodeName line: {described}"));
        let node = match node.split_once(' ') {
            Some((_, rest)) => format!("NodeName=localhost {rest}"),
            None => panic!("slurmd -C: unexpected line `{node}`"),
        };
        let d = dir.display();
        let conf = format!(
            "ClusterName=eyebot{pid}\n\
             SlurmctldHost=localhost\n\
             SlurmctldPort={ctld_port}\n\
             SlurmdPort={slurmd_port}\n\
             SlurmUser={user}\n\
             AuthType=auth/munge\n\
             AuthInfo=socket={socket}\n\
             CredType=cred/munge\n\
             StateSaveLocation={d}/state\n\
             SlurmdSpoolDir={d}/spool\n\
             SlurmctldPidFile={d}/slurmctld.pid\n\
             SlurmdPidFile={d}/slurmd.pid\n\
             SlurmctldLogFile={d}/log/slurmctld.log\n\
             SlurmdLogFile={d}/log/slurmd.log\n\
             ProctrackType=proctrack/linuxproc\n\
             TaskPlugin=task/none\n\
             SelectType=select/cons_tres\n\
             SelectTypeParameters=CR_Core\n\
             AccountingStorageType=accounting_storage/none\n\
             JobCompType=jobcomp/filetxt\n\
             JobCompLoc={jobcomp}\n\
             MpiDefault=none\n\
             ReturnToService=2\n\
             {node}\n\
             PartitionName=test Nodes=localhost Default=YES MaxTime=INFINITE State=UP\n",
            pid = std::process::id(),
            ctld_port = free_tcp_port(),
            slurmd_port = free_tcp_port(),
            user = user_name(),
            socket = socket.display(),
            jobcomp = cluster.jobcomp.display(),
        );
        std::fs::write(&cluster.conf, conf).expect("write slurm.conf");
        let log = |name: &str| {
            std::fs::File::create(dir.join("log").join(name)).expect("daemon log file")
        };
        cluster.slurmctld = Some(ChildGuard::spawn(
            "slurmctld",
            Command::new(slurmctld)
                .args(["-D", "-i"])
                .env("SLURM_CONF", &cluster.conf)
                .stdout(log("slurmctld.out"))
                .stderr(log("slurmctld.err")),
        ));
        cluster.slurmd = Some(ChildGuard::spawn(
            "slurmd",
            Command::new(slurmd)
                .args(["-D", "-N", "localhost"])
                .env("SLURM_CONF", &cluster.conf)
                .stdout(log("slurmd.out"))
                .stderr(log("slurmd.err")),
        ));
        wait_for("the node to be idle", Duration::from_secs(60), || {
            for daemon in [&mut cluster.slurmctld, &mut cluster.slurmd]
                .into_iter()
                .flatten()
            {
                daemon.assert_running();
            }
            let out = cluster
                .command("sinfo")
                .args(["-h", "-o", "%t"])
                .output()
                .ok()?;
            (String::from_utf8_lossy(&out.stdout).trim() == "idle").then_some(())
        });
        cluster
    }

    /// A Slurm client command talking to this cluster.
    fn command(&self, program: &str) -> Command {
        let mut c = Command::new(program);
        c.env("SLURM_CONF", &self.conf);
        c
    }

    /// The end state of job `id` (for an array, of every task) once it has ended, from the
    /// job completion log.
    fn end_states(&self, id: &str) -> Vec<String> {
        let text = std::fs::read_to_string(&self.jobcomp).unwrap_or_default();
        text.lines()
            .filter(|l| {
                l.contains(&format!("JobId={id} ")) || l.contains(&format!("ArrayJobId={id} "))
            })
            .filter_map(|l| {
                l.split_whitespace()
                    .find_map(|w| w.strip_prefix("JobState="))
                    .map(str::to_string)
            })
            .collect()
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        if !self.jobs.is_empty() {
            let _ = self.command("scancel").args(&self.jobs).status();
        }
        // The node, the controller, then munge: each is killed and reaped.
        drop(self.slurmd.take());
        drop(self.slurmctld.take());
        drop(self.munged.take());
    }
}

fn user_name() -> String {
    let out = Command::new("id").arg("-un").output().expect("run id -un");
    String::from_utf8_lossy(&out.stdout).trim().to_string()
}

/// The results with wall time left out, the one field that differs run to run.
fn timeless(results: &[CaseResult]) -> Vec<CaseResult> {
    results
        .iter()
        .cloned()
        .map(|mut r| {
            r.seconds = 0.0;
            r
        })
        .collect()
}

/// The per-case lines of an `--out` report, each without its last field (wall time).
fn case_lines(report: &str) -> Vec<String> {
    report
        .lines()
        .skip_while(|l| !l.starts_with("index,"))
        .map(|l| match l.rsplit_once(',') {
            Some((head, _)) => head.to_string(),
            None => l.to_string(),
        })
        .collect()
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("read {}: {e}", path.display()))
}

/// Every log of the campaign, to show when it failed.
fn logs(work: &Path) -> String {
    let mut text = String::new();
    if let Ok(entries) = std::fs::read_dir(work.join("logs")) {
        let mut paths: Vec<PathBuf> = entries.flatten().map(|e| e.path()).collect();
        paths.sort();
        for p in paths {
            text.push_str(&format!("--- {}\n{}", p.display(), read(&p)));
        }
    }
    text
}

#[test]
fn the_documented_slurm_recipe_merges_to_the_unsharded_run() {
    let exe = PathBuf::from(env!("CARGO_BIN_EXE_eyebot-hil"));
    let dir = TempDir::new("gap-slurm");
    let mut cluster = Cluster::start(&dir.join("cluster"));
    let work = dir.join("campaign");
    let submit = workspace_root().join("docs/gap/slurm/submit.sh");

    let out = cluster
        .command("bash")
        .arg(&submit)
        .arg(&work)
        .arg(SHARDS.to_string())
        .args(CAMPAIGN)
        .env("EYEBOT_HIL", &exe)
        .env("GAP_CPUS_PER_TASK", "1")
        .output()
        .expect("run submit.sh");
    assert!(
        out.status.success(),
        "submit.sh failed ({}): {}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    let ids: Vec<String> = String::from_utf8_lossy(&out.stdout)
        .split_whitespace()
        .map(str::to_string)
        .collect();
    assert_eq!(
        ids.len(),
        3,
        "submit.sh prints calibration, array and merge job ids"
    );
    cluster.jobs = ids.clone();
    let (calibration, array, merge) = (&ids[0], &ids[1], &ids[2]);

    // The unsharded run of the same campaign, while the cluster works.
    let whole_part = dir.join("whole.json");
    let whole_report = dir.join("whole.md");
    let status = Command::new(&exe)
        .arg("gap-bench")
        .args(CAMPAIGN)
        .args(["--shard", "1/1", "--out-part"])
        .arg(&whole_part)
        .arg("--out")
        .arg(&whole_report)
        .env("RAYON_NUM_THREADS", "1")
        .stdout(Stdio::null())
        .status()
        .expect("run the unsharded campaign");
    assert!(status.success(), "unsharded gap-bench: {status}");

    let states = wait_for("the merge job to end", Duration::from_secs(900), || {
        let s = cluster.end_states(merge);
        (!s.is_empty()).then_some(s)
    });
    assert_eq!(
        states,
        vec!["COMPLETED".to_string()],
        "merge job {merge}; logs:\n{}",
        logs(&work)
    );
    assert_eq!(
        cluster.end_states(calibration),
        vec!["COMPLETED".to_string()]
    );
    assert_eq!(
        cluster.end_states(array),
        vec!["COMPLETED".to_string(); SHARDS],
        "one completed task per shard"
    );

    // Merged == unsharded, case by case.
    let whole = Part::read(&whole_part).expect("the unsharded part");
    assert_eq!(
        whole.results.len(),
        3,
        "two effects and the nulls, one case each"
    );
    let parts: Vec<(PathBuf, Part)> = (1..=SHARDS)
        .map(|k| {
            let p = work.join(format!("parts/part-{k}.json"));
            let part = Part::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            (p, part)
        })
        .collect();
    let (key, merged) = bench::merge(&parts).expect("the parts merge");
    assert_eq!(key, whole.options);
    assert_eq!(timeless(&merged.results), timeless(&whole.results));
    assert_eq!(
        case_lines(&read(&work.join("bench.md"))),
        case_lines(&read(&whole_report)),
        "the merge job's report"
    );

    // One calibration, read by both shards; a progress line per case in each shard's log.
    let log_names: Vec<String> = std::fs::read_dir(work.join("logs"))
        .expect("logs directory")
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(
        log_names
            .iter()
            .filter(|n| n.starts_with("calibrate-"))
            .count(),
        1
    );
    assert!(work.join("calibration.json").is_file());
    for (k, (_, part)) in parts.iter().enumerate() {
        let log = read(&work.join(format!("logs/shard-{array}_{}.out", k + 1)));
        for r in &part.results {
            let line = format!("gap-bench: shard {}/{SHARDS}: ", k + 1);
            assert!(
                log.lines().any(|l| l.starts_with(&line)
                    && l.contains(&format!(": case {} {}: ", r.index, r.label))),
                "shard {} log shows no line for case {}:\n{log}",
                k + 1,
                r.index
            );
        }
    }
}

/// The command a Slurm step of the recipe runs (its `exec` line, continuation lines joined),
/// with the staged binary called by name, the campaign's options (`"$@"`) as `options` and
/// the task number and count as K and N.
fn slurm_step(script: &str, options: &str) -> String {
    let text = read(&workspace_root().join("docs/gap/slurm").join(script));
    let joined = text.replace("\\\n", " ");
    let exec = joined
        .lines()
        .find(|l| l.starts_with("exec "))
        .unwrap_or_else(|| panic!("{script} has no exec line"));
    normalise(
        &exec
            .replace("bin/eyebot-hil", "eyebot-hil")
            .replace("\"$@\"", options)
            .replace("$k", "K")
            .replace("$n", "N"),
    )
}

fn normalise(command: &str) -> String {
    command.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// A Kubernetes manifest of the recipe, parsed.
fn manifest(name: &str) -> serde_json::Value {
    let path = workspace_root().join("docs/gap/kubernetes").join(name);
    serde_json::from_str(&read(&path)).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// A Job's one container, its `sh -c` script's `exec` command, and the container.
fn job_command(job: &serde_json::Value) -> (String, serde_json::Value) {
    let container = job["spec"]["template"]["spec"]["containers"][0].clone();
    let command = container["command"].clone();
    assert_eq!(command[0], "sh", "{command}");
    assert_eq!(command[1], "-c", "{command}");
    let script = command[2].as_str().expect("the script is a string");
    let exec = script
        .split("&&")
        .map(str::trim)
        .find(|s| s.starts_with("exec "))
        .unwrap_or_else(|| panic!("no exec in `{script}`"));
    (normalise(exec), container)
}

/// The Kubernetes Indexed Job of `docs/gap.md` cannot run here (no cluster images can be
/// fetched); its manifests are held to the Slurm recipe instead: they parse, share a
/// ReadWriteMany volume, run each step's command (the shard's with the completion index plus
/// one as its task number, so parts are numbered 1..N as on Slurm, and N equal to the Job's
/// completions), and give rayon the CPUs they request.
#[test]
fn the_kubernetes_jobs_run_the_slurm_steps() {
    let volume = manifest("volume.json");
    assert_eq!(volume["kind"], "PersistentVolumeClaim");
    assert_eq!(
        volume["spec"]["accessModes"],
        serde_json::json!(["ReadWriteMany"])
    );
    let claim = volume["metadata"]["name"].clone();

    let (calibrate, _) = job_command(&manifest("calibrate.json"));
    let options = calibrate
        .strip_prefix("exec eyebot-hil gap-bench calibrate ")
        .and_then(|rest| rest.strip_suffix(" --out calibration.json"))
        .unwrap_or_else(|| panic!("calibrate.json runs `{calibrate}`"))
        .to_string();
    assert_eq!(calibrate, slurm_step("calibrate.sbatch", &options));

    let shards = manifest("shards.json");
    assert_eq!(shards["spec"]["completionMode"], "Indexed");
    let n = shards["spec"]["completions"]
        .as_u64()
        .expect("completions is a number");
    let (shard, _) = job_command(&shards);
    let shard = shard
        .replace("$((JOB_COMPLETION_INDEX + 1))", "K")
        .replace(&format!("K/{n}\""), "K/N\"");
    assert_eq!(shard, slurm_step("shard.sbatch", &options));

    let (merge, _) = job_command(&manifest("merge.json"));
    assert_eq!(merge, slurm_step("merge.sbatch", &options));

    for name in ["calibrate.json", "shards.json", "merge.json"] {
        let job = manifest(name);
        let (_, container) = job_command(&job);
        assert_eq!(container["workingDir"], "/work", "{name}");
        assert_eq!(container["volumeMounts"][0]["mountPath"], "/work", "{name}");
        assert_eq!(
            job["spec"]["template"]["spec"]["volumes"][0]["persistentVolumeClaim"]["claimName"],
            claim,
            "{name}"
        );
        let rayon = container["env"]
            .as_array()
            .and_then(|env| env.iter().find(|e| e["name"] == "RAYON_NUM_THREADS"))
            .map(|e| e["value"].clone());
        assert_eq!(
            rayon,
            Some(container["resources"]["requests"]["cpu"].clone()),
            "{name}: rayon threads = CPUs requested"
        );
    }
}
