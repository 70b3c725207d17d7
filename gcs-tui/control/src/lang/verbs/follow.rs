//! `follow ROBOT LEADER DX,DY` / `follow ROBOT none`: puts a robot under
//! follow-the-leader at an offset in the leader's frame (route it to
//! `follow/LEADER`), or takes it out.

use mech_proto::Offset;

use super::control_error;
use crate::hub::follow_channel;
use crate::lang::args::{Args, Target};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};
use crate::spec::parse_offset;

/// Make `follower` follow `leader` at `offset` (m, leader frame); no leader:
/// follow nobody.
#[derive(Debug, Clone, PartialEq)]
pub struct Follow {
    pub follower: Target,
    pub leader: Option<Target>,
    pub offset: Offset,
}

impl Follow {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<Follow, LangError> {
        let follower = a.target()?;
        if a.keyword("none") {
            return Ok(Follow {
                follower,
                leader: None,
                offset: Offset { x: 0.0, y: 0.0 },
            });
        }
        let leader = a.target()?;
        let w = a.next("offset dx,dy (m, leader frame)")?;
        let offset = parse_offset(&w.text).map_err(|e| LangError::new(w.span, e.to_string()))?;
        Ok(Follow {
            follower,
            leader: Some(leader),
            offset,
        })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, _at: Span) -> Result<Outcome, LangError> {
        let (follower, offset) = (&self.follower, self.offset);
        let Some(leader) = &self.leader else {
            ctx.control.unfollow(&follower.name);
            return Ok(Outcome::new(format!("{} follows nobody", follower.name)));
        };
        ctx.control
            .follow(&follower.name, &leader.name, offset)
            .map_err(|e| control_error(follower, e))?;
        Ok(Outcome::new(format!(
            "{} follows {} at {},{} m (leader frame); route it to {}",
            follower.name,
            leader.name,
            offset.x,
            offset.y,
            follow_channel(&leader.name)
        )))
    }
}
