//! `spawn N`: starts simulated agents through the executor's
//! [`SimSpawner`](crate::lang::SimSpawner), when the build has one.

use std::net::{IpAddr, Ipv4Addr};

use crate::lang::args::Args;
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// The most agents one `spawn` starts: a typo must not fork-bomb the host.
const MAX_SPAWN: u64 = 10_000;

/// Start `count` simulated agents registering with this station's router.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Spawn {
    pub count: usize,
}

impl Spawn {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<Spawn, LangError> {
        let span = a.peek().map_or(a.end(), |w| w.span);
        let n = a.count("number of simulated agents")?;
        if n == 0 || n > MAX_SPAWN {
            return Err(LangError::new(
                span,
                format!("spawn between 1 and {MAX_SPAWN} agents"),
            ));
        }
        Ok(Spawn { count: n as usize })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, at: Span) -> Result<Outcome, LangError> {
        let mut router = ctx.gcs.router().udp_addr();
        if router.ip().is_unspecified() {
            router.set_ip(IpAddr::V4(Ipv4Addr::LOCALHOST));
        }
        let spawner = ctx.spawner.as_mut().ok_or_else(|| {
            LangError::new(at, "simulated agents are not available in this build")
        })?;
        let names = spawner
            .spawn(self.count, router, ctx.gcs.router().clone())
            .await
            .map_err(|e| LangError::new(at, format!("cannot spawn simulated agents: {e}")))?;
        Ok(Outcome::new(format!("spawned {}", names.join(", "))))
    }
}
