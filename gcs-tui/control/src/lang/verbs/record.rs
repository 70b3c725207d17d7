//! `record start [FILE]`, `record stop`, `record toggle`, `record`:
//! recording everything the router sees to MCAP (`docs/recording.md`). Without a file, `record
//! start` writes rotating files into the recording directory (`[record]
//! dir`, or the log directory).

use std::path::PathBuf;

use mech_core::{RecordTarget, RecordingStatus};

use crate::lang::args::Args;
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// What `record` does.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Record {
    /// Start recording, to this file or (`None`) to rotating files.
    Start(Option<PathBuf>),
    Stop,
    /// Stop if recording, else start into the recording directory (the
    /// TUI's record key).
    Toggle,
    /// Say how the recording is going.
    Status,
}

impl Record {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<Record, LangError> {
        let record = if a.is_empty() {
            Record::Status
        } else if a.keyword("start") {
            match a.peek() {
                Some(_) => Record::Start(Some(PathBuf::from(&a.next("file")?.text))),
                None => Record::Start(None),
            }
        } else if a.keyword("stop") {
            Record::Stop
        } else if a.keyword("toggle") {
            Record::Toggle
        } else {
            let w = a.next("start, stop, toggle or nothing")?;
            return Err(LangError::new(
                w.span,
                format!("expected start, stop, toggle or nothing, got {:?}", w.text),
            ));
        };
        a.finish()?;
        Ok(record)
    }

    pub(super) async fn apply(&self, ctx: &mut Context, at: Span) -> Result<Outcome, LangError> {
        match self {
            Record::Toggle => {
                let recording = ctx.gcs.recording().is_some_and(|s| s.active);
                let then = if recording {
                    Record::Stop
                } else {
                    Record::Start(None)
                };
                Box::pin(then.apply(ctx, at)).await
            }
            Record::Start(file) => {
                let target = match (file, &ctx.record_dir) {
                    (Some(f), _) => RecordTarget::File(f.clone()),
                    (None, Some(dir)) => ctx.gcs.config().record.rotating(dir),
                    (None, None) => {
                        return Err(LangError::new(
                            at,
                            "no recording directory here: record start FILE",
                        ));
                    }
                };
                let path = ctx
                    .gcs
                    .start_recording(target)
                    .map_err(|e| LangError::new(at, e.to_string()))?;
                Ok(Outcome::new(format!("recording to {}", path.display())))
            }
            Record::Stop => match ctx.gcs.stop_recording().await {
                Some(s) => Ok(Outcome::new(format!("stopped: {}", describe(&s)))),
                None => Err(LangError::new(at, "not recording")),
            },
            Record::Status => Ok(Outcome::new(match ctx.gcs.recording() {
                Some(s) => describe(&s),
                None => "not recording".into(),
            })),
        }
    }
}

/// One line about a recording: file, size, what it holds, what it lost.
pub fn describe(s: &RecordingStatus) -> String {
    let state = if s.active { "recording" } else { "recorded" };
    let mut line = format!(
        "{state} {} ({:.1} MB, {} router messages, {} events, {} dropped",
        s.file.display(),
        s.bytes as f64 / 1e6,
        s.messages,
        s.events,
        s.dropped
    );
    if s.refused_unrecorded > 0 {
        line.push_str(&format!(
            ", {} refused messages counted, not recorded",
            s.refused_unrecorded
        ));
    }
    if s.files.len() > 1 {
        line.push_str(&format!(", file {} of a rotation", s.files.len()));
    }
    line.push(')');
    if let Some(e) = &s.error {
        line.push_str(&format!("; FAILED: {e}"));
    }
    line
}
