//! Keyboard teleoperation on channel `key/0`, for machines without a pad.
//!
//! Terminals report key presses (and auto-repeats) but usually not
//! releases, so each press holds its direction for a short window that the
//! terminal's auto-repeat keeps refreshing; when every direction has lapsed
//! one `Stop` is published and the channel goes silent. If the terminal does
//! report releases, [`KeyTeleop::release`] ends a direction at once.

use std::time::{Duration, Instant};

use mech_proto::{Command, Stop, Twist};

use super::mapping::Limits;

/// The keyboard teleop channel.
pub const KEY_CHANNEL: &str = "key/0";

/// A driving key (arrows / WASD, Q/E strafe, R/F climb and descend: a
/// flying robot's vertical speed, which a ground robot ignores).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DriveKey {
    Forward,
    Back,
    TurnLeft,
    TurnRight,
    StrafeLeft,
    StrafeRight,
    Climb,
    Descend,
}

/// How many driving keys there are.
const KEYS: usize = 8;

impl DriveKey {
    /// Every driving key.
    pub const ALL: [DriveKey; KEYS] = [
        DriveKey::Forward,
        DriveKey::Back,
        DriveKey::TurnLeft,
        DriveKey::TurnRight,
        DriveKey::StrafeLeft,
        DriveKey::StrafeRight,
        DriveKey::Climb,
        DriveKey::Descend,
    ];

    fn index(self) -> usize {
        self as usize
    }
}

/// Keyboard teleop state: which directions are held, until when.
#[derive(Debug, Clone)]
pub struct KeyTeleop {
    limits: Limits,
    /// How long one press (or auto-repeat) keeps a direction held.
    pub hold: Duration,
    period: Duration,
    held_until: [Option<Instant>; KEYS],
    last_sent: Option<Instant>,
    /// A command has been published since the last stop.
    moving: bool,
    pub last: Option<Command>,
}

impl Default for KeyTeleop {
    fn default() -> Self {
        Self::new(Limits::default(), 20.0)
    }
}

impl KeyTeleop {
    pub fn new(limits: Limits, rate_hz: f64) -> Self {
        let hz = if rate_hz.is_finite() && rate_hz > 0.0 {
            rate_hz
        } else {
            20.0
        };
        Self {
            limits,
            hold: Duration::from_millis(550),
            period: Duration::from_nanos((1e9 / hz).round() as u64),
            held_until: [None; KEYS],
            last_sent: None,
            moving: false,
            last: None,
        }
    }

    /// A drive key was pressed or auto-repeated: publish at once.
    pub fn press(&mut self, key: DriveKey, now: Instant) -> Option<Command> {
        self.held_until[key.index()] = Some(now + self.hold);
        // Opposite directions cancel the other at once.
        let opposite = match key {
            DriveKey::Forward => DriveKey::Back,
            DriveKey::Back => DriveKey::Forward,
            DriveKey::TurnLeft => DriveKey::TurnRight,
            DriveKey::TurnRight => DriveKey::TurnLeft,
            DriveKey::StrafeLeft => DriveKey::StrafeRight,
            DriveKey::StrafeRight => DriveKey::StrafeLeft,
            DriveKey::Climb => DriveKey::Descend,
            DriveKey::Descend => DriveKey::Climb,
        };
        self.held_until[opposite.index()] = None;
        Some(self.send(now))
    }

    /// The terminal reported a key release.
    pub fn release(&mut self, key: DriveKey, now: Instant) -> Option<Command> {
        self.held_until[key.index()] = None;
        self.tick(now)
    }

    /// Stop now (space bar): forget every held direction, publish `Stop`.
    pub fn stop(&mut self, now: Instant) -> Command {
        self.held_until = [None; KEYS];
        self.moving = false;
        self.last_sent = Some(now);
        let c = Command::Stop(Stop {});
        self.last = Some(c.clone());
        c
    }

    /// Steady-rate republish while a direction is held; one `Stop` when the
    /// last one lapses.
    pub fn tick(&mut self, now: Instant) -> Option<Command> {
        for slot in &mut self.held_until {
            if slot.is_some_and(|t| now >= t) {
                *slot = None;
            }
        }
        if self.held_until.iter().all(Option::is_none) {
            return self.moving.then(|| self.stop(now));
        }
        let due = self
            .last_sent
            .is_none_or(|t| now.saturating_duration_since(t) + self.period / 10 >= self.period);
        due.then(|| self.send(now))
    }

    /// Whether any direction is held now.
    pub fn driving(&self) -> bool {
        self.moving
    }

    fn held(&self, key: DriveKey) -> f64 {
        if self.held_until[key.index()].is_some() {
            1.0
        } else {
            0.0
        }
    }

    fn send(&mut self, now: Instant) -> Command {
        let twist = Twist {
            vx: (self.held(DriveKey::Forward) - self.held(DriveKey::Back)) * self.limits.max_speed,
            vy: (self.held(DriveKey::StrafeLeft) - self.held(DriveKey::StrafeRight))
                * self.limits.max_speed,
            // The platform's own climb limit caps it on the robot.
            vz: (self.held(DriveKey::Climb) - self.held(DriveKey::Descend)) * self.limits.max_speed,
            wz: (self.held(DriveKey::TurnLeft) - self.held(DriveKey::TurnRight))
                * self.limits.max_yaw_rate,
        };
        self.moving = true;
        self.last_sent = Some(now);
        let c = Command::Twist(twist);
        self.last = Some(c.clone());
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn press_drives_forward_at_once() {
        let mut k = KeyTeleop::default();
        let now = Instant::now();
        let Some(Command::Twist(t)) = k.press(DriveKey::Forward, now) else {
            panic!("twist expected");
        };
        assert_eq!(t.vx, Limits::default().max_speed);
        assert_eq!(t.wz, 0.0);
    }

    #[test]
    fn lapsed_hold_publishes_one_stop_then_silence() {
        let mut k = KeyTeleop::default();
        let now = Instant::now();
        k.press(DriveKey::TurnLeft, now);
        assert!(matches!(
            k.tick(now + Duration::from_millis(100)),
            Some(Command::Twist(_))
        ));
        let after = now + k.hold + Duration::from_millis(1);
        assert_eq!(k.tick(after), Some(Command::Stop(Stop {})));
        assert_eq!(k.tick(after + Duration::from_secs(1)), None);
        assert!(!k.driving());
    }

    #[test]
    fn release_stops_at_once() {
        let mut k = KeyTeleop::default();
        let now = Instant::now();
        k.press(DriveKey::Back, now);
        assert_eq!(
            k.release(DriveKey::Back, now + Duration::from_millis(5)),
            Some(Command::Stop(Stop {}))
        );
    }

    #[test]
    fn auto_repeat_keeps_driving_and_combines_keys() {
        let mut k = KeyTeleop::default();
        let now = Instant::now();
        k.press(DriveKey::Forward, now);
        let later = now + Duration::from_millis(400);
        k.press(DriveKey::Forward, later);
        let Some(Command::Twist(t)) = k.press(DriveKey::TurnRight, later) else {
            panic!("twist expected");
        };
        assert!(t.vx > 0.0 && t.wz < 0.0);
        assert!(matches!(
            k.tick(now + Duration::from_millis(700)),
            Some(Command::Twist(_))
        ));
    }

    #[test]
    fn all_keys_are_distinct_slots() {
        let idx: std::collections::HashSet<_> = DriveKey::ALL.iter().map(|k| k.index()).collect();
        assert_eq!(idx.len(), KEYS);
        assert!(idx.iter().all(|i| *i < KEYS));
    }

    #[test]
    fn climb_and_descend_set_the_vertical_speed_and_cancel_each_other() {
        let mut k = KeyTeleop::default();
        let now = Instant::now();
        let Some(Command::Twist(up)) = k.press(DriveKey::Climb, now) else {
            panic!("twist expected");
        };
        assert_eq!(up.vz, Limits::default().max_speed);
        assert_eq!((up.vx, up.vy, up.wz), (0.0, 0.0, 0.0));
        let later = now + Duration::from_millis(10);
        let Some(Command::Twist(t)) = k.press(DriveKey::Forward, later) else {
            panic!("twist expected");
        };
        assert!(t.vx > 0.0 && t.vz > 0.0, "climbing while flying forward");
        let Some(Command::Twist(down)) = k.press(DriveKey::Descend, later) else {
            panic!("twist expected");
        };
        assert_eq!(
            down.vz,
            -Limits::default().max_speed,
            "descend replaced climb"
        );
    }
}
