//! What the layer does on its own to keep robots moving: the right-hand
//! rule that turns a command's way aside of the neighbours it would meet
//! ([`circulation`], [`super::NeighbourSet::anticipate`]), and backing a
//! stuck robot off from its neighbours, the last resort. Safety never
//! depends on either: whatever they choose, the constraints judge.

use std::time::Duration;

use super::circulation;
use super::filter::{self, Decision, Mobility, decide};
use super::{BACK_OFF_SPEED, BackOff, Constraints, STILL, SafetyLayer, Vec2, along_cell_edge};

impl SafetyLayer {
    /// Ends whatever the layer was doing on its own (backing off, carrying
    /// a swerve's speed, timing a jam): a robot held still for another
    /// reason (e-stop, failsafe, no position) or no longer limited starts
    /// afresh from its next command, and a turn on the spot then never
    /// moves it.
    pub(super) fn forget_manoeuvre(&mut self) {
        self.backing_off = None;
        self.circling = None;
        self.stuck_since = None;
        self.turning_since = None;
    }

    /// The decision: a robot backing off keeps at it; otherwise the
    /// right-hand rule ([`circulation`]) turns the way its command heads
    /// for to the right of every neighbour it would meet, recomputed every
    /// period from where the robots are (no timers), and the constraints
    /// judge the result.
    pub(super) fn decide(
        &mut self,
        c: &Constraints,
        desired: Vec2,
        twist: &mech_proto::Twist,
        mobility: &Mobility,
        margin: f64,
        now: Duration,
    ) -> Decision {
        let wants_motion = [twist.vx, twist.vy, twist.wz]
            .iter()
            .any(|v| v.abs() > 1e-9);
        if !wants_motion {
            self.forget_manoeuvre();
        }
        if let Some(y) = self.backing_off.filter(|y| now < y.until) {
            return filter::steer(c, y.target, mobility);
        }
        self.backing_off = None;
        let intent =
            circulation::intent(desired, twist, mobility, self.bearing_gain, self.circling);
        let swerve = self.swerve(c, intent, margin, now);
        // A diff-drive driven backwards swerves backwards.
        let steering = if !mobility.holonomic && twist.vx < 0.0 {
            mobility.rear_first()
        } else {
            *mobility
        };
        // A diff-drive turning on the spot towards its swerve is under
        // way, not stuck: for as long as half a turn takes.
        let turning =
            swerve.is_some_and(|t| !mobility.holonomic && filter::turns_first(t, &steering));
        let moving = mobility.velocity.norm() >= STILL;
        if self.turning_excused(turning, moving, now) {
            self.stuck_since = None;
        } else if let Some(back_off) = self.unstick(c, intent, mobility, wants_motion, margin, now)
        {
            self.circling = None;
            return back_off;
        }
        match swerve {
            Some(target) => {
                // The speed when the rule took over, kept while it holds
                // (for a command that steers towards a bearing only).
                if self.bearing_gain.is_some() {
                    self.circling.get_or_insert(intent.norm());
                }
                filter::steer(c, target, &steering)
            }
            None => {
                self.circling = None;
                decide(c, desired, mobility)
            }
        }
    }

    /// Whether a diff-drive `turning` on the spot towards its swerve at
    /// `now` is excused from being stuck: only until it has turned, since
    /// it last moved, for as long as half a turn takes at
    /// `yield_turn_rate`, the most any swerve needs. Turns with breaks in
    /// between add up (a controller that stops driving to turn whenever it
    /// is off its heading flips between turning and not every period). A
    /// robot still turning after that is not getting round (its wheels
    /// slip, or the swerve keeps moving round it), and the stuck timer
    /// judges it as any other.
    fn turning_excused(&mut self, turning: bool, moving: bool, now: Duration) -> bool {
        if moving {
            self.turning_since = None;
        }
        if !turning {
            return false;
        }
        let since = *self.turning_since.get_or_insert(now);
        let half_turn = std::f64::consts::PI / self.config.yield_turn_rate;
        now.saturating_sub(since).as_secs_f64() <= half_turn
    }

    /// The right-hand rule: `intent` turned right by the smallest angle
    /// that meets no neighbour within `horizon`
    /// ([`super::NeighbourSet::anticipate`]). `None`: the way is clear (or
    /// the look-ahead is off).
    fn swerve(&self, c: &Constraints, intent: Vec2, margin: f64, now: Duration) -> Option<Vec2> {
        let n = self
            .neighbours
            .as_ref()
            .filter(|_| self.config.horizon > 0.0)?;
        let target = n.anticipate(
            c.position,
            intent,
            self.footprint(),
            margin,
            self.config.horizon,
            now,
        )?;
        Some(along_cell_edge(c, target))
    }

    /// Deadlock breaking, the last resort behind the right-hand rule: a
    /// robot that has wanted to move for `stuck_after` s (plus 0.3 s per
    /// its id modulo 5, so robots jammed together do not all move at once)
    /// without moving, and headed somewhere meanwhile (`intent`, see
    /// [`circulation::intent`]: a turn on the spot the rule did not take
    /// over, or a crawl slower than [`STILL`], is not being stuck), backs
    /// off from the neighbours near it for `back_off_time` s, at up to
    /// [`BACK_OFF_SPEED`], within the constraints as always. `None`: it is
    /// not stuck (or nobody is near to back off from).
    fn unstick(
        &mut self,
        c: &Constraints,
        intent: Vec2,
        mobility: &Mobility,
        wants_motion: bool,
        margin: f64,
        now: Duration,
    ) -> Option<Decision> {
        if self.config.stuck_after <= 0.0 || !wants_motion || mobility.velocity.norm() >= STILL {
            self.stuck_since = None;
            return None;
        }
        let (since, going) = self.stuck_since.get_or_insert((now, false));
        *going |= intent.norm() >= STILL;
        let (since, going) = (*since, *going);
        let wait = self.config.stuck_after + 0.3 * f64::from(self.id.unwrap_or(0) % 5);
        if !going || now.saturating_sub(since).as_secs_f64() <= wait {
            return None;
        }
        let away = self
            .neighbours
            .as_ref()?
            .away(c.position, self.footprint(), margin, now)?;
        self.stuck_since = None;
        self.turning_since = None;
        let target = away * BACK_OFF_SPEED;
        self.backing_off = Some(BackOff {
            target,
            until: now + Duration::from_secs_f64(self.config.back_off_time),
        });
        Some(filter::steer(c, target, mobility))
    }
}
