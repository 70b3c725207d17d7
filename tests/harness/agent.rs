//! Simulated robots as `mech-agent` processes (in a network namespace or
//! not), stopped cleanly (SIGTERM: they print their counters) or killed
//! (SIGKILL, as `kill -9`) and restarted.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use serde_json::Value;

use super::Killed;
use super::netns::RobotNet;

/// A simulated robot's config: a diff-drive at (`x`, 1), links and
/// failsafe as given (TOML lines).
pub fn config(dir: &Path, name: &str, x: f64, links: &str, failsafe: &str) -> PathBuf {
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(
        &path,
        format!(
            "name = \"{name}\"\ntelemetry_rate_hz = 20\n{links}\n\
             [platform]\nkind = \"diff-drive\"\ntrack_width = 0.15\nmax_wheel_speed = 0.5\n\
             [position]\nkind = \"sim\"\n[sim]\nx = {x}\ny = 1.0\nnoise = false\n\
             [failsafe]\n{failsafe}\n"
        ),
    )
    .expect("agent config written");
    path
}

/// A running agent.
#[derive(Debug)]
pub struct Agent {
    pub name: String,
    config: PathBuf,
    process: Killed,
}

impl Agent {
    /// Starts `mech-agent --config CONFIG` (inside `net` if given).
    pub fn start(name: &str, config: &Path, net: Option<&RobotNet>) -> Agent {
        let mut a = Agent {
            name: name.to_string(),
            config: config.to_path_buf(),
            process: Killed(None),
        };
        a.restart(net);
        a
    }

    /// Starts it again (after [`Agent::kill`]).
    pub fn restart(&mut self, net: Option<&RobotNet>) {
        let bin = crate::binary("mech-agent");
        let mut cmd = match net {
            Some(n) => n.command(&bin),
            None => Command::new(bin),
        };
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(self.config.with_extension("log"))
            .expect("agent log opens");
        let child = cmd
            .arg("--config")
            .arg(&self.config)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(log)
            .spawn()
            .expect("mech-agent starts (the test command builds it first)");
        self.process = Killed(Some(child));
    }

    /// What it logged (all runs), for failure messages.
    pub fn log(&self) -> String {
        std::fs::read_to_string(self.config.with_extension("log")).unwrap_or_default()
    }

    /// Kills it (SIGKILL): no Bye, no counters.
    pub fn kill(&mut self) {
        self.process.kill();
    }

    /// Stops it cleanly (SIGTERM) and returns the counters it printed.
    pub fn stop(&mut self) -> Option<Value> {
        let mut child = self.process.0.take()?;
        let _ = Command::new("kill")
            .args(["-TERM", &child.id().to_string()])
            .status();
        let (tx, rx) = std::sync::mpsc::channel();
        if let Some(mut stdout) = child.stdout.take() {
            std::thread::spawn(move || {
                let mut out = String::new();
                let _ = stdout.read_to_string(&mut out);
                let _ = tx.send(out);
            });
        }
        // An agent that does not stop within 10 s is killed, counters lost.
        let out = rx
            .recv_timeout(std::time::Duration::from_secs(10))
            .unwrap_or_default();
        let _ = child.kill();
        let _ = child.wait();
        out.lines()
            .filter_map(|l| serde_json::from_str::<Value>(l).ok())
            .find_map(|v| v.get("agent_counters").cloned())
    }
}
