//! What the fleet model makes of fleet safety's events: the station's
//! arena, each robot's switch as an operator set it, and what robots'
//! layers report, as log lines (`docs/safety.md`).

use mech_proto::{Intervention, SafetyState};

use super::{Fleet, Severity};
use crate::arena::ArenaShape;
use crate::event::Event;

impl Fleet {
    /// One of fleet safety's events (others are ignored here).
    pub(super) fn safety_event(&mut self, e: &Event) {
        match e {
            Event::Arena { arena } => self.arena_changed(arena),
            Event::SafetySwitched { robot, enabled, id } => {
                self.safety_switched(robot, *enabled, *id)
            }
            Event::ArenaAcked { robot, id, enabled } => self.arena_acked(robot, *id, *enabled),
            Event::Safety {
                robot,
                state,
                intervention,
            } => self.safety_reported(robot, *state, *intervention),
            _ => {}
        }
    }

    fn arena_changed(&mut self, arena: &Option<ArenaShape>) {
        self.arena.clone_from(arena);
        let text = match arena {
            Some(a) => format!("arena: {}", a.summary()),
            None => "arena cleared: robots keep no fence".to_string(),
        };
        self.log(Severity::Info, text);
    }

    fn safety_switched(&mut self, robot: &str, enabled: bool, id: u32) {
        if let Some(r) = self.robots.get_mut(robot) {
            r.safety_enabled = enabled;
        }
        if enabled {
            self.log(
                Severity::Info,
                format!("{robot}: safety on requested (arena {id})"),
            );
        } else {
            self.log(
                Severity::Warn,
                format!("{robot}: safety OFF requested by an operator (arena {id})"),
            );
        }
    }

    fn arena_acked(&mut self, robot: &str, id: u32, enabled: bool) {
        let on = if enabled { "on" } else { "OFF" };
        self.log(
            Severity::Info,
            format!("{robot} acknowledged arena {id} (safety {on})"),
        );
    }

    /// A robot's layer reports a new state or intervention. The
    /// interventions themselves reach the log as the robot's notices (at
    /// most one a second each); a state change is logged here.
    fn safety_reported(&mut self, robot: &str, state: SafetyState, _intervention: Intervention) {
        let Some(r) = self.robots.get(robot) else {
            return;
        };
        let was = r.telemetry.safety.map(|s| s.state);
        if was == Some(state) {
            return;
        }
        match state {
            SafetyState::Off => self.log(
                Severity::Warn,
                format!("{robot} reports safety OFF: not kept inside the arena or apart"),
            ),
            SafetyState::On => self.log(Severity::Info, format!("{robot} reports safety on")),
            SafetyState::NoArena => {}
        }
    }
}
