//! A TUI in a detached tmux session: keys and SGR mouse clicks go in with
//! `send-keys`, the screen comes back with `capture-pane -p`; and readers
//! of the robot cards on that screen.

use std::process::{Command, Output};
use std::time::{Duration, Instant};

pub struct Tmux {
    pub socket: String,
    pub session: String,
    /// A directory removed with the server.
    pub state: std::path::PathBuf,
}

impl Tmux {
    /// `mech-gcs --demo 2` in a detached tmux session `gcs` of `w` x `h`
    /// cells; `id` names the tmux server and the temporary directory the
    /// station keeps its state in.
    pub fn demo(id: &str, w: u16, h: u16) -> Tmux {
        let state = std::env::temp_dir().join(id);
        std::fs::create_dir_all(&state).expect("temp dir");
        let cmd = format!(
            "XDG_STATE_HOME={} {} --demo 2 --udp 127.0.0.1:0 --tcp 127.0.0.1:0",
            state.display(),
            mech_e2e::binary("mech-gcs").display()
        );
        let tmux = Tmux {
            socket: id.to_string(),
            session: "gcs".into(),
            state,
        };
        let (ws, hs) = (w.to_string(), h.to_string());
        let out = tmux.run(&["new-session", "-d", "-s", "gcs", "-x", &ws, "-y", &hs, &cmd]);
        assert!(out.status.success(), "tmux new-session: {out:?}");
        tmux
    }

    pub fn run(&self, args: &[&str]) -> Output {
        Command::new("tmux")
            .arg("-L")
            .arg(&self.socket)
            .args(args)
            .output()
            .unwrap_or_else(|e| panic!("tmux {args:?}: {e}"))
    }

    pub fn keys(&self, keys: &[&str]) {
        let mut args = vec!["send-keys", "-t", self.session.as_str()];
        args.extend_from_slice(keys);
        let out = self.run(&args);
        assert!(out.status.success(), "send-keys {keys:?}");
    }

    pub fn literal(&self, text: &str) {
        let out = self.run(&["send-keys", "-t", &self.session, "-l", text]);
        assert!(out.status.success(), "send-keys -l {text:?}");
    }

    pub fn screen(&self) -> String {
        String::from_utf8_lossy(
            &self
                .run(&["capture-pane", "-p", "-t", &self.session])
                .stdout,
        )
        .into_owned()
    }

    /// Waits until `pred` holds for the screen; panics with the screen after
    /// `timeout`.
    pub fn wait_for(&self, what: &str, timeout: Duration, pred: impl Fn(&str) -> bool) -> String {
        let start = Instant::now();
        loop {
            let s = self.screen();
            if pred(&s) {
                return s;
            }
            if start.elapsed() > timeout {
                panic!("timed out waiting for {what}; screen:\n{s}");
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }
}

impl Drop for Tmux {
    fn drop(&mut self) {
        let _ = self.run(&["kill-session", "-t", &self.session]);
        let _ = self.run(&["kill-server"]);
        let _ = std::fs::remove_dir_all(&self.state);
    }
}

/// The card line after robot_1's title: " x  0.91 y  0.83 z ..." -> (x, y).
pub fn card_position(screen: &str, robot: &str) -> Option<(f64, f64)> {
    let mut lines = screen.lines();
    lines.find(|l| l.contains(&format!("{robot} #")))?;
    let pose = lines.next()?;
    let after_x = pose.split(" x").nth(1)?;
    let mut parts = after_x.split(" y");
    let x: f64 = parts.next()?.trim().parse().ok()?;
    let y: f64 = parts.next()?.split_whitespace().next()?.parse().ok()?;
    Some((x, y))
}

/// Third line of a robot's card (mode, route, failsafe, mission).
pub fn card_status(screen: &str, robot: &str) -> String {
    let mut lines = screen.lines();
    if lines.find(|l| l.contains(&format!("{robot} #"))).is_none() {
        return String::new();
    }
    lines.nth(1).unwrap_or_default().to_string()
}
