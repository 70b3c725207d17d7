//! `cluster NAME ROBOT...`: names a set of registered robots, so commands
//! can target them together.

use crate::lang::args::{Args, Target};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// Define (or redefine) cluster `name` as `members`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Cluster {
    pub name: String,
    pub members: Vec<Target>,
}

impl Cluster {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<Cluster, LangError> {
        let name = a.next("cluster name")?;
        if name.text == "all" {
            return Err(LangError::new(
                name.span,
                "`all` is reserved for every robot",
            ));
        }
        let mut members = Vec::new();
        while !a.is_empty() {
            members.push(a.target()?);
        }
        if members.is_empty() {
            return Err(a.missing("robot"));
        }
        Ok(Cluster {
            name: name.text.clone(),
            members,
        })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, _at: Span) -> Result<Outcome, LangError> {
        let mut names = Vec::new();
        for m in &self.members {
            let known = ctx
                .gcs
                .with_fleet(|f| f.robot(&m.name).map(|r| r.is_local()));
            match known {
                None => {
                    return Err(LangError::new(
                        m.span,
                        format!("no robot named {:?}", m.name),
                    ));
                }
                Some(false) => {
                    return Err(LangError::new(
                        m.span,
                        format!("{} is another station's robot, shown read-only", m.name),
                    ));
                }
                Some(true) => {}
            }
            names.push(m.name.clone());
        }
        ctx.gcs
            .update_fleet(|f| f.set_cluster(&self.name, names.clone()));
        Ok(Outcome::new(format!(
            "cluster {}: {}",
            self.name,
            names.join(", ")
        )))
    }
}
