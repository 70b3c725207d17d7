//! `drive TARGET NUMBER...`: one command in each robot's mode (set by
//! `mode`) on the GCS command channel, and how it was delivered.

use mech_core::router::Delivery;
use mech_proto::{
    Actuators, Command as Cmd, CommandKind, SteeringThrottle, Stop, Twist, VelocityHeading,
};

use crate::lang::args::{Args, Target};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// Publish one command built from `values` to every robot of `target`.
#[derive(Debug, Clone, PartialEq)]
pub struct Drive {
    pub target: Target,
    pub values: Vec<f64>,
}

impl Drive {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<Drive, LangError> {
        let target = a.target()?;
        let mut values = Vec::new();
        while !a.is_empty() {
            values.push(a.number("value")?);
        }
        Ok(Drive { target, values })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, _at: Span) -> Result<Outcome, LangError> {
        let target = &self.target;
        let robots = ctx.resolve(target)?;
        let channel = ctx.gcs.config().fleet.command_channel.clone();
        let mut report = Vec::new();
        for r in &robots {
            let mode = ctx.gcs.with_fleet(|f| f.robot(r).and_then(|x| x.gcs_mode));
            let mode = mode.ok_or_else(|| {
                LangError::new(
                    target.span,
                    format!("{r} has no drive mode; set one with `mode {r} MODE`"),
                )
            })?;
            let cmd = command(mode, &self.values).map_err(|m| LangError::new(target.span, m))?;
            let delivery = ctx
                .publishers
                .on(&channel)
                .send(r, cmd)
                .await
                .map_err(|e| LangError::new(target.span, e.to_string()))?;
            report.push(match delivery {
                Delivery::Forwarded(_) => format!("{r}: forwarded"),
                Delivery::Dropped(reason) => {
                    format!("{r}: dropped ({}; route it to {channel})", reason.as_str())
                }
                Delivery::Consumed => format!("{r}: consumed"),
            });
        }
        Ok(Outcome::new(format!("{channel}: {}", report.join(", "))))
    }
}

/// Builds a command of `mode` from the numbers written after `drive`.
pub fn command(mode: CommandKind, v: &[f64]) -> Result<Cmd, String> {
    let need = |n: usize| -> Result<(), String> {
        if v.len() == n {
            Ok(())
        } else {
            Err(format!("{mode} takes {n} numbers, got {}", v.len()))
        }
    };
    let cmd = match mode {
        CommandKind::Actuators => Cmd::Actuators(Actuators {
            outputs: v.to_vec(),
        }),
        CommandKind::SteeringThrottle => {
            need(2)?;
            Cmd::SteeringThrottle(SteeringThrottle {
                steering: v[0],
                throttle: v[1],
            })
        }
        CommandKind::VelocityHeading => {
            need(2)?;
            Cmd::VelocityHeading(VelocityHeading {
                speed: v[0],
                heading: v[1],
            })
        }
        CommandKind::Twist => match v {
            [vx, vy, wz] => Cmd::Twist(Twist {
                vx: *vx,
                vy: *vy,
                vz: 0.0,
                wz: *wz,
            }),
            [vx, vy, vz, wz] => Cmd::Twist(Twist {
                vx: *vx,
                vy: *vy,
                vz: *vz,
                wz: *wz,
            }),
            _ => {
                return Err(format!(
                    "twist takes vx vy wz or vx vy vz wz, got {} numbers",
                    v.len()
                ));
            }
        },
        CommandKind::Stop => {
            need(0)?;
            Cmd::Stop(Stop {})
        }
        CommandKind::Waypoints => {
            return Err("waypoints are sent with `waypoint` and `send`".into());
        }
    };
    cmd.validate().map_err(|e| e.to_string())?;
    Ok(cmd)
}
