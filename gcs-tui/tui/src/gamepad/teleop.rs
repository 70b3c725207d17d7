//! Gamepad teleoperation: turns pad events into commands on channel `joy/N`.
//!
//! A pad drives only while its dead-man button is held (configurable). It
//! publishes at once on any input change and again at a steady rate while
//! enabled, so the agent's channel-silence failsafe never trips on a held
//! stick. Releasing the dead-man or unplugging the pad publishes one zero
//! command and then silence. Time is passed in, never read, so the rate and
//! the release logic are tested without sleeping.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use super::input::{PadAxis, PadButton, PadEvent, PadEventKind, PadId};
use super::mapping::{Limits, Mapped, Sticks, TeleopMode, map};
use super::shaping::Shaping;

/// Tunables for every pad.
#[derive(Debug, Clone, PartialEq)]
pub struct TeleopConfig {
    /// Button that must be held to drive; `None` disables the dead-man (the
    /// pad drives whenever connected).
    pub deadman: Option<PadButton>,
    /// Cycles [`TeleopMode`].
    pub mode_button: PadButton,
    /// Engages the fleet e-stop, whatever the dead-man.
    pub estop_button: PadButton,
    /// Steady publish rate while enabled, Hz.
    pub rate_hz: f64,
    pub shaping: Shaping,
    pub limits: Limits,
    /// Mode a newly connected pad starts in.
    pub initial_mode: TeleopMode,
}

impl Default for TeleopConfig {
    fn default() -> Self {
        Self {
            deadman: Some(PadButton::LeftBumper),
            mode_button: PadButton::Select,
            estop_button: PadButton::Start,
            rate_hz: 20.0,
            shaping: Shaping::default(),
            limits: Limits::default(),
            initial_mode: TeleopMode::default(),
        }
    }
}

impl TeleopConfig {
    /// Time between steady publishes: one over [`TeleopConfig::rate_hz`],
    /// or that of 20 Hz when the rate is not a positive number, so the
    /// station's teleop clock and the pads' own rate check agree.
    pub fn period(&self) -> Duration {
        let hz = if self.rate_hz.is_finite() && self.rate_hz > 0.0 {
            self.rate_hz
        } else {
            20.0
        };
        Duration::from_nanos((1e9 / hz).round() as u64)
    }
}

/// Raw axis values as last reported by the pad.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct RawAxes {
    left_x: f64,
    left_y: f64,
    right_x: f64,
    right_y: f64,
    left_trigger: f64,
    right_trigger: f64,
}

impl RawAxes {
    fn set(&mut self, axis: PadAxis, v: f64) {
        let slot = match axis {
            PadAxis::LeftStickX => &mut self.left_x,
            PadAxis::LeftStickY => &mut self.left_y,
            PadAxis::RightStickX => &mut self.right_x,
            PadAxis::RightStickY => &mut self.right_y,
            PadAxis::LeftTrigger => &mut self.left_trigger,
            PadAxis::RightTrigger => &mut self.right_trigger,
        };
        *slot = v;
    }

    /// Every axis through the stick shaping; triggers never go negative.
    fn shaped(&self, s: &Shaping) -> Sticks {
        Sticks {
            left_x: s.apply(self.left_x),
            left_y: s.apply(self.left_y),
            right_x: s.apply(self.right_x),
            right_y: s.apply(self.right_y),
            left_trigger: s.apply(self.left_trigger).max(0.0),
            right_trigger: s.apply(self.right_trigger).max(0.0),
        }
    }
}

/// What one pad is doing, for display and for the publish logic.
#[derive(Debug, Clone, PartialEq)]
pub struct PadState {
    pub id: PadId,
    /// Name the backend reported.
    pub name: String,
    pub mode: TeleopMode,
    /// Dead-man held (or no dead-man configured).
    pub enabled: bool,
    /// Shaped inputs.
    pub sticks: Sticks,
    /// Last output published, if any.
    pub last: Option<Mapped>,
    /// The channel it publishes on.
    channel: String,
    raw: RawAxes,
    last_sent: Option<Instant>,
    last_heading: f64,
}

impl PadState {
    /// A pad just plugged in: sticks centred, nothing published yet,
    /// enabled at once only when no dead-man is configured.
    fn new(id: PadId, name: &str, config: &TeleopConfig, channel: String) -> PadState {
        PadState {
            id,
            channel,
            name: name.to_string(),
            mode: config.initial_mode,
            enabled: config.deadman.is_none(),
            sticks: Sticks::default(),
            last: None,
            raw: RawAxes::default(),
            last_sent: None,
            last_heading: 0.0,
        }
    }

    /// The channel this pad publishes on.
    pub fn channel(&self) -> String {
        self.channel.clone()
    }
}

/// What the teleop logic wants the ground station to do.
#[derive(Debug, Clone, PartialEq)]
pub enum TeleopAction {
    /// Publish this on the channel: a [`mech_proto::Command`] goes to every
    /// robot the router has routed to the channel; a cluster velocity goes to
    /// the cluster being driven.
    Publish(Mapped),
    /// Engage the fleet e-stop.
    EStop,
    /// A pad appeared (name) and now owns the channel.
    Connected(String),
    /// A pad went away (its zero command precedes this).
    Disconnected,
    ModeChanged(TeleopMode),
}

/// One output of the teleop logic, on a controller channel.
#[derive(Debug, Clone, PartialEq)]
pub struct TeleopOutput {
    /// `joy/N` or `key/0`.
    pub channel: String,
    pub action: TeleopAction,
}

/// All connected pads and their publish logic.
#[derive(Debug, Clone)]
pub struct Teleop {
    config: TeleopConfig,
    pads: BTreeMap<PadId, PadState>,
    /// Channel prefix of the pads: pad N publishes on `PREFIX/N`.
    prefix: String,
}

impl Default for Teleop {
    fn default() -> Self {
        Teleop::new(TeleopConfig::default())
    }
}

impl Teleop {
    pub fn new(config: TeleopConfig) -> Self {
        Self {
            config,
            pads: BTreeMap::new(),
            prefix: "joy".into(),
        }
    }

    /// Pads publish on `PREFIX/N` from now on (the station names each
    /// operator's pads); pads already connected keep their channel until
    /// they reconnect.
    pub fn set_channel_prefix(&mut self, prefix: &str) {
        self.prefix = prefix.to_string();
    }

    /// The channel pad `id` publishes on.
    fn channel_of(&self, id: PadId) -> String {
        self.pads
            .get(&id)
            .map_or_else(|| id.channel_in(&self.prefix), PadState::channel)
    }

    pub fn config(&self) -> &TeleopConfig {
        &self.config
    }

    /// Connected pads, by id.
    pub fn pads(&self) -> impl Iterator<Item = &PadState> {
        self.pads.values()
    }

    pub fn pad(&self, id: PadId) -> Option<&PadState> {
        self.pads.get(&id)
    }

    /// Applies one pad event and returns what to publish now.
    pub fn handle(&mut self, ev: &PadEvent, now: Instant) -> Vec<TeleopOutput> {
        match &ev.kind {
            PadEventKind::Connected(name) => self.connect(ev.pad, name),
            PadEventKind::Disconnected => self.disconnect(ev.pad),
            PadEventKind::ButtonPressed(b) => self.press(ev.pad, *b, now),
            PadEventKind::ButtonReleased(b) => self.release(ev.pad, *b, now),
            PadEventKind::AxisChanged(axis, v) => self.move_axis(ev.pad, *axis, *v, now),
        }
    }

    /// A pad (re)appears and owns its channel; one that was already there
    /// under this id first publishes a stop.
    fn connect(&mut self, id: PadId, name: &str) -> Vec<TeleopOutput> {
        let mut out = Vec::new();
        if let Some(old) = self.pads.remove(&id) {
            out.push(publish(&old.channel, Mapped::zero(old.mode)));
        }
        let channel = id.channel_in(&self.prefix);
        let pad = PadState::new(id, name, &self.config, channel.clone());
        self.pads.insert(id, pad);
        out.push(TeleopOutput {
            channel,
            action: TeleopAction::Connected(name.to_string()),
        });
        out
    }

    /// A pad goes away: one stop, then silence.
    fn disconnect(&mut self, id: PadId) -> Vec<TeleopOutput> {
        let Some(old) = self.pads.remove(&id) else {
            return Vec::new();
        };
        let channel = old.channel;
        vec![
            publish(&channel, Mapped::zero(old.mode)),
            TeleopOutput {
                channel,
                action: TeleopAction::Disconnected,
            },
        ]
    }

    /// The e-stop button (whatever the dead-man), the dead-man, or the mode
    /// button, which stops the old mode's output before the new one's.
    fn press(&mut self, id: PadId, b: PadButton, now: Instant) -> Vec<TeleopOutput> {
        let mut out = Vec::new();
        let channel = self.channel_of(id);
        let Some(pad) = self.pads.get_mut(&id) else {
            return out;
        };
        if b == self.config.estop_button {
            out.push(TeleopOutput {
                channel,
                action: TeleopAction::EStop,
            });
        } else if Some(b) == self.config.deadman {
            pad.enabled = true;
            send_mapped(pad, &self.config, now, true, &mut out);
        } else if b == self.config.mode_button {
            let old = pad.mode;
            pad.mode = old.next();
            out.push(TeleopOutput {
                channel: channel.clone(),
                action: TeleopAction::ModeChanged(pad.mode),
            });
            if pad.enabled {
                let zero = Mapped::zero(old);
                pad.last = Some(zero.clone());
                out.push(publish(&channel, zero));
                send_mapped(pad, &self.config, now, true, &mut out);
            }
        }
        out
    }

    /// Letting go of the dead-man publishes one stop.
    fn release(&mut self, id: PadId, b: PadButton, now: Instant) -> Vec<TeleopOutput> {
        let Some(pad) = self.pads.get_mut(&id) else {
            return Vec::new();
        };
        if Some(b) != self.config.deadman || !pad.enabled {
            return Vec::new();
        }
        pad.enabled = false;
        let zero = Mapped::zero(pad.mode);
        pad.last = Some(zero.clone());
        pad.last_sent = Some(now);
        vec![publish(&pad.channel, zero)]
    }

    /// A stick or trigger moved: reshape, and publish if enabled and the
    /// output changed.
    fn move_axis(&mut self, id: PadId, axis: PadAxis, v: f64, now: Instant) -> Vec<TeleopOutput> {
        let mut out = Vec::new();
        let Some(pad) = self.pads.get_mut(&id) else {
            return out;
        };
        pad.raw.set(axis, v);
        pad.sticks = pad.raw.shaped(&self.config.shaping);
        if pad.enabled {
            send_mapped(pad, &self.config, now, false, &mut out);
        }
        out
    }

    /// Steady-rate republish: every enabled pad whose last publish is at
    /// least one period old publishes its current output again.
    pub fn tick(&mut self, now: Instant) -> Vec<TeleopOutput> {
        let period = self.config.period();
        let mut out = Vec::new();
        for pad in self.pads.values_mut() {
            if !pad.enabled {
                continue;
            }
            // A tenth of a period of slack, so a tick that arrives a little
            // early (timer jitter) does not halve the rate.
            let due = pad
                .last_sent
                .is_none_or(|t| now.saturating_duration_since(t) + period / 10 >= period);
            if due {
                send_mapped(pad, &self.config, now, true, &mut out);
            }
        }
        out
    }
}

fn publish(channel: &str, m: Mapped) -> TeleopOutput {
    TeleopOutput {
        channel: channel.to_string(),
        action: TeleopAction::Publish(m),
    }
}

/// Publishes the pad's mapped output; unless `force`, only if it changed.
fn send_mapped(
    pad: &mut PadState,
    config: &TeleopConfig,
    now: Instant,
    force: bool,
    out: &mut Vec<TeleopOutput>,
) {
    let m = map(pad.mode, &pad.sticks, &config.limits, pad.last_heading);
    if let Mapped::Command(mech_proto::Command::VelocityHeading(v)) = &m {
        pad.last_heading = v.heading;
    }
    if !force && pad.last.as_ref() == Some(&m) {
        return;
    }
    pad.last = Some(m.clone());
    pad.last_sent = Some(now);
    out.push(publish(&pad.channel, m));
}

#[cfg(test)]
mod tests {
    use mech_proto::{Command, Stop, Twist};

    use super::*;

    fn ev(kind: PadEventKind) -> PadEvent {
        PadEvent::new(0, kind)
    }

    fn published(out: &[TeleopOutput]) -> Vec<Mapped> {
        out.iter()
            .filter_map(|o| match &o.action {
                TeleopAction::Publish(m) => Some(m.clone()),
                _ => None,
            })
            .collect()
    }

    fn twist_pad() -> (Teleop, Instant) {
        let mut t = Teleop::new(TeleopConfig {
            initial_mode: TeleopMode::Twist,
            shaping: Shaping {
                deadzone: 0.1,
                expo: 0.0,
            },
            ..TeleopConfig::default()
        });
        let now = Instant::now();
        t.handle(&ev(PadEventKind::Connected("test pad".into())), now);
        (t, now)
    }

    #[test]
    fn nothing_is_published_without_the_deadman() {
        let (mut t, now) = twist_pad();
        let out = t.handle(
            &ev(PadEventKind::AxisChanged(PadAxis::LeftStickY, 1.0)),
            now,
        );
        assert!(published(&out).is_empty());
        assert!(t.tick(now + Duration::from_secs(1)).is_empty());
    }

    #[test]
    fn deadman_held_drives_and_release_zeroes_once() {
        let (mut t, now) = twist_pad();
        t.handle(
            &ev(PadEventKind::AxisChanged(PadAxis::LeftStickY, 1.0)),
            now,
        );
        let out = t.handle(&ev(PadEventKind::ButtonPressed(PadButton::LeftBumper)), now);
        let p = published(&out);
        assert_eq!(p.len(), 1);
        let Mapped::Command(Command::Twist(tw)) = &p[0] else {
            panic!("twist expected, got {p:?}");
        };
        assert!((tw.vx - Limits::default().max_speed).abs() < 1e-12);
        assert_eq!(out[0].channel, "joy/0");

        let out = t.handle(
            &ev(PadEventKind::ButtonReleased(PadButton::LeftBumper)),
            now + Duration::from_millis(10),
        );
        assert_eq!(
            published(&out),
            vec![Mapped::Command(Command::Stop(Stop {}))]
        );
        assert!(
            t.tick(now + Duration::from_secs(2)).is_empty(),
            "silent after the zero"
        );
    }

    #[test]
    fn stick_inside_deadzone_commands_zero() {
        let (mut t, now) = twist_pad();
        t.handle(&ev(PadEventKind::ButtonPressed(PadButton::LeftBumper)), now);
        t.handle(
            &ev(PadEventKind::AxisChanged(PadAxis::LeftStickY, 0.08)),
            now,
        );
        t.handle(
            &ev(PadEventKind::AxisChanged(PadAxis::RightStickX, -0.05)),
            now,
        );
        let out = t.tick(now + Duration::from_millis(50));
        assert_eq!(
            published(&out),
            vec![Mapped::Command(Command::Twist(Twist::default()))]
        );
    }

    #[test]
    fn unplug_zeroes_the_channel_even_without_deadman() {
        let (mut t, now) = twist_pad();
        t.handle(&ev(PadEventKind::ButtonPressed(PadButton::LeftBumper)), now);
        t.handle(
            &ev(PadEventKind::AxisChanged(PadAxis::LeftStickY, 0.9)),
            now,
        );
        let out = t.handle(&ev(PadEventKind::Disconnected), now);
        assert_eq!(
            published(&out),
            vec![Mapped::Command(Command::Stop(Stop {}))]
        );
        assert_eq!(out[0].channel, "joy/0");
        assert!(t.pads().next().is_none());
        assert!(t.tick(now + Duration::from_secs(1)).is_empty());
    }

    #[test]
    fn steady_rate_while_enabled() {
        let (mut t, now) = twist_pad();
        t.handle(&ev(PadEventKind::ButtonPressed(PadButton::LeftBumper)), now);
        // 20 Hz: ticks every 10 ms for one second publish ~20 times.
        let mut n = 0;
        for i in 1..=100 {
            n += published(&t.tick(now + Duration::from_millis(10 * i))).len();
        }
        assert_eq!(n, 20);
    }

    #[test]
    fn slightly_early_ticks_keep_the_rate() {
        let (mut t, now) = twist_pad();
        t.handle(&ev(PadEventKind::ButtonPressed(PadButton::LeftBumper)), now);
        // Ticks every 49 ms (timer jitter) still publish every tick.
        let n: usize = (1..=20)
            .map(|i| published(&t.tick(now + Duration::from_millis(49 * i))).len())
            .sum();
        assert_eq!(n, 20);
    }

    #[test]
    fn input_change_publishes_at_once_but_repeats_do_not() {
        let (mut t, now) = twist_pad();
        t.handle(&ev(PadEventKind::ButtonPressed(PadButton::LeftBumper)), now);
        let a = t.handle(
            &ev(PadEventKind::AxisChanged(PadAxis::LeftStickY, 0.5)),
            now,
        );
        assert_eq!(published(&a).len(), 1);
        let b = t.handle(
            &ev(PadEventKind::AxisChanged(PadAxis::LeftStickY, 0.5)),
            now,
        );
        assert!(published(&b).is_empty());
    }

    #[test]
    fn mode_button_cycles_and_estop_always_works() {
        let (mut t, now) = twist_pad();
        let out = t.handle(&ev(PadEventKind::ButtonPressed(PadButton::Select)), now);
        assert!(out.contains(&TeleopOutput {
            channel: "joy/0".into(),
            action: TeleopAction::ModeChanged(TeleopMode::Cluster)
        }));
        let out = t.handle(&ev(PadEventKind::ButtonPressed(PadButton::Start)), now);
        assert_eq!(out[0].action, TeleopAction::EStop);
    }

    #[test]
    fn mode_change_while_driving_zeroes_old_mode_first() {
        let (mut t, now) = twist_pad();
        t.handle(&ev(PadEventKind::ButtonPressed(PadButton::LeftBumper)), now);
        let out = t.handle(&ev(PadEventKind::ButtonPressed(PadButton::Select)), now);
        let p = published(&out);
        assert_eq!(p[0], Mapped::Command(Command::Stop(Stop {})));
        assert!(matches!(p[1], Mapped::Cluster(_)));
    }

    #[test]
    fn second_pad_is_its_own_channel() {
        let (mut t, now) = twist_pad();
        t.handle(
            &PadEvent::new(1, PadEventKind::Connected("other".into())),
            now,
        );
        let out = t.handle(
            &PadEvent::new(1, PadEventKind::ButtonPressed(PadButton::LeftBumper)),
            now,
        );
        assert_eq!(out[0].channel, "joy/1");
        assert_eq!(t.pads().count(), 2);
    }

    #[test]
    fn an_attached_operators_pads_publish_under_their_prefix() {
        let (mut t, now) = twist_pad();
        t.set_channel_prefix("joy/ana");
        t.handle(
            &PadEvent::new(1, PadEventKind::Connected("other".into())),
            now,
        );
        let out = t.handle(
            &PadEvent::new(1, PadEventKind::ButtonPressed(PadButton::LeftBumper)),
            now,
        );
        assert_eq!(out[0].channel, "joy/ana/1");
        assert_eq!(t.pad(PadId(1)).unwrap().channel(), "joy/ana/1");
        // A pad connected before keeps its channel until it reconnects.
        assert_eq!(t.pad(PadId(0)).unwrap().channel(), "joy/0");
    }

    #[test]
    fn without_deadman_configured_the_pad_drives() {
        let mut t = Teleop::new(TeleopConfig {
            deadman: None,
            ..TeleopConfig::default()
        });
        let now = Instant::now();
        t.handle(&ev(PadEventKind::Connected("p".into())), now);
        let out = t.handle(
            &ev(PadEventKind::AxisChanged(PadAxis::LeftStickY, 1.0)),
            now,
        );
        assert_eq!(published(&out).len(), 1);
    }
}
