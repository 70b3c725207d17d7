//! Input abstraction for gamepads: the pad events the teleop logic consumes,
//! a source trait, the production gilrs source and a scripted source.
//!
//! gilrs is not `Send` on every platform and blocks on its own event queue, so
//! production code polls it on a dedicated thread ([`spawn_pump`]) and hands
//! plain [`PadEvent`]s to the async side; tests feed the same events from a
//! [`ScriptedSource`], since no physical pad exists in CI.

use std::collections::VecDeque;
use std::time::Duration;

use thiserror::Error;

/// Stable number of a gamepad for this run (gilrs keeps the id of a pad that
/// is unplugged and plugged in again), used as the `N` of channel `joy/N`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct PadId(pub usize);

impl PadId {
    /// The controller channel this pad publishes on: `joy/N`.
    pub fn channel(self) -> String {
        self.channel_in("joy")
    }

    /// The channel under `prefix`: `PREFIX/N` (an attached operator's pads
    /// are `joy/OPERATOR/N`).
    pub fn channel_in(self, prefix: &str) -> String {
        format!("{prefix}/{}", self.0)
    }
}

mech_proto::named_enum! {
    /// Buttons the teleop logic understands (the SDL / gilrs layout names).
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
    pub enum PadButton: "button" {
        South => "south",
        East => "east",
        North => "north",
        West => "west",
        LeftBumper => "left-bumper",
        RightBumper => "right-bumper",
        LeftTrigger => "left-trigger",
        RightTrigger => "right-trigger",
        Select => "select",
        Start => "start",
        Mode => "mode",
        LeftThumb => "left-thumb",
        RightThumb => "right-thumb",
        DPadUp => "dpad-up",
        DPadDown => "dpad-down",
        DPadLeft => "dpad-left",
        DPadRight => "dpad-right",
    }
}

/// Analogue axes, each in `[-1, 1]`; stick Y is positive when pushed away
/// from the user, triggers run `0..1`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PadAxis {
    LeftStickX,
    LeftStickY,
    RightStickX,
    RightStickY,
    LeftTrigger,
    RightTrigger,
}

/// What happened on one pad.
#[derive(Debug, Clone, PartialEq)]
pub enum PadEventKind {
    /// The pad appeared (at start-up or hot-plugged), with its name.
    Connected(String),
    /// The pad went away; its channel must be zeroed.
    Disconnected,
    ButtonPressed(PadButton),
    ButtonReleased(PadButton),
    AxisChanged(PadAxis, f64),
}

/// One input event from one pad.
#[derive(Debug, Clone, PartialEq)]
pub struct PadEvent {
    pub pad: PadId,
    pub kind: PadEventKind,
}

impl PadEvent {
    pub fn new(pad: usize, kind: PadEventKind) -> Self {
        Self {
            pad: PadId(pad),
            kind,
        }
    }
}

/// Anything that yields pad events without blocking.
pub trait InputSource {
    /// The next pending event, or `None` when nothing is waiting.
    fn next_event(&mut self) -> Option<PadEvent>;
}

/// A pre-recorded sequence of events (tests, replays).
#[derive(Debug, Default)]
pub struct ScriptedSource {
    events: VecDeque<PadEvent>,
}

impl ScriptedSource {
    pub fn new(events: impl IntoIterator<Item = PadEvent>) -> Self {
        Self {
            events: events.into_iter().collect(),
        }
    }

    pub fn push(&mut self, event: PadEvent) {
        self.events.push_back(event);
    }
}

impl InputSource for ScriptedSource {
    fn next_event(&mut self) -> Option<PadEvent> {
        self.events.pop_front()
    }
}

/// Why the gamepad subsystem could not start.
#[derive(Debug, Error)]
pub enum GamepadError {
    #[error("gamepad backend unavailable: {0}")]
    Backend(String),
    #[error("cannot start the gamepad thread: {0}")]
    Thread(#[from] std::io::Error),
}

/// Real gamepads through gilrs.
pub struct GilrsSource {
    gilrs: gilrs::Gilrs,
    /// Pads already present at start-up, reported as `Connected` first.
    initial: VecDeque<PadEvent>,
}

impl std::fmt::Debug for GilrsSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GilrsSource")
            .field("pending", &self.initial.len())
            .finish()
    }
}

impl GilrsSource {
    /// Opens the platform gamepad backend. Works with zero pads connected.
    pub fn new() -> Result<Self, GamepadError> {
        let gilrs = match gilrs::Gilrs::new() {
            Ok(g) => g,
            Err(gilrs::Error::NotImplemented(g)) => g,
            Err(e) => return Err(GamepadError::Backend(e.to_string())),
        };
        let initial = gilrs
            .gamepads()
            .map(|(id, pad)| {
                PadEvent::new(
                    usize::from(id),
                    PadEventKind::Connected(pad.name().to_string()),
                )
            })
            .collect();
        Ok(Self { gilrs, initial })
    }
}

impl InputSource for GilrsSource {
    fn next_event(&mut self) -> Option<PadEvent> {
        if let Some(e) = self.initial.pop_front() {
            return Some(e);
        }
        while let Some(ev) = self.gilrs.next_event() {
            let pad = usize::from(ev.id);
            let kind = match ev.event {
                gilrs::EventType::Connected => {
                    let name = self.gilrs.gamepad(ev.id).name().to_string();
                    Some(PadEventKind::Connected(name))
                }
                gilrs::EventType::Disconnected => Some(PadEventKind::Disconnected),
                gilrs::EventType::ButtonPressed(b, _) => button(b).map(PadEventKind::ButtonPressed),
                gilrs::EventType::ButtonReleased(b, _) => {
                    button(b).map(PadEventKind::ButtonReleased)
                }
                gilrs::EventType::ButtonChanged(b, v, _) => match b {
                    gilrs::Button::LeftTrigger2 => Some(PadEventKind::AxisChanged(
                        PadAxis::LeftTrigger,
                        f64::from(v),
                    )),
                    gilrs::Button::RightTrigger2 => Some(PadEventKind::AxisChanged(
                        PadAxis::RightTrigger,
                        f64::from(v),
                    )),
                    _ => None,
                },
                gilrs::EventType::AxisChanged(a, v, _) => {
                    axis(a).map(|a| PadEventKind::AxisChanged(a, f64::from(v)))
                }
                _ => None,
            };
            if let Some(kind) = kind {
                return Some(PadEvent {
                    pad: PadId(pad),
                    kind,
                });
            }
        }
        None
    }
}

fn button(b: gilrs::Button) -> Option<PadButton> {
    use gilrs::Button as B;
    Some(match b {
        B::South => PadButton::South,
        B::East => PadButton::East,
        B::North => PadButton::North,
        B::West => PadButton::West,
        B::LeftTrigger => PadButton::LeftBumper,
        B::RightTrigger => PadButton::RightBumper,
        B::LeftTrigger2 => PadButton::LeftTrigger,
        B::RightTrigger2 => PadButton::RightTrigger,
        B::Select => PadButton::Select,
        B::Start => PadButton::Start,
        B::Mode => PadButton::Mode,
        B::LeftThumb => PadButton::LeftThumb,
        B::RightThumb => PadButton::RightThumb,
        B::DPadUp => PadButton::DPadUp,
        B::DPadDown => PadButton::DPadDown,
        B::DPadLeft => PadButton::DPadLeft,
        B::DPadRight => PadButton::DPadRight,
        _ => return None,
    })
}

fn axis(a: gilrs::Axis) -> Option<PadAxis> {
    use gilrs::Axis as A;
    Some(match a {
        A::LeftStickX => PadAxis::LeftStickX,
        A::LeftStickY => PadAxis::LeftStickY,
        A::RightStickX => PadAxis::RightStickX,
        A::RightStickY => PadAxis::RightStickY,
        A::LeftZ => PadAxis::LeftTrigger,
        A::RightZ => PadAxis::RightTrigger,
        _ => return None,
    })
}

/// Polls gilrs on its own thread and forwards events into `tx` until the
/// receiver is dropped. Returns at once; the thread exits with the receiver.
pub fn spawn_pump(
    tx: tokio::sync::mpsc::UnboundedSender<PadEvent>,
) -> Result<std::thread::JoinHandle<()>, GamepadError> {
    let handle = std::thread::Builder::new()
        .name("gamepad".into())
        .spawn(move || {
            let mut source = match GilrsSource::new() {
                Ok(s) => s,
                Err(e) => {
                    tracing::warn!("gamepads disabled: {e}");
                    return;
                }
            };
            loop {
                while let Some(ev) = source.next_event() {
                    if tx.send(ev).is_err() {
                        return;
                    }
                }
                if tx.is_closed() {
                    return;
                }
                std::thread::sleep(Duration::from_millis(5));
            }
        })?;
    Ok(handle)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scripted_source_yields_in_order_then_none() {
        let mut s = ScriptedSource::new([
            PadEvent::new(0, PadEventKind::Connected("pad".into())),
            PadEvent::new(0, PadEventKind::ButtonPressed(PadButton::South)),
        ]);
        assert_eq!(
            s.next_event().map(|e| e.kind),
            Some(PadEventKind::Connected("pad".into()))
        );
        assert!(s.next_event().is_some());
        assert!(s.next_event().is_none());
    }

    #[test]
    fn pad_channel_is_joy_n() {
        assert_eq!(PadId(3).channel(), "joy/3");
    }

    #[test]
    fn gilrs_opens_without_pads() {
        // The backend must start on a machine with no pad (CI, SSH hosts).
        let mut src = GilrsSource::new().expect("gilrs backend");
        while src.next_event().is_some() {}
    }
}
