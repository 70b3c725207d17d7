//! `record start [FILE [overwrite]]`, `record stop`, `record toggle`,
//! `record`: recording everything the router sees to MCAP
//! (`docs/recording.md`). Without a file, `record start` writes rotating
//! files into the recording directory (`[record] dir`, or the log
//! directory). A file is a new one unless the command says `overwrite`;
//! from an operator's session it is a name in the recording directory
//! ([`crate::files`]).

use mech_core::{RecordTarget, RecordingStatus};

use crate::lang::args::Args;
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// What `record` does.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Record {
    /// Start recording, to this file or (`None`) to rotating files.
    Start(Option<RecordFile>),
    Stop,
    /// Stop if recording, else start into the recording directory (the
    /// TUI's record key).
    Toggle,
    /// Say how the recording is going.
    Status,
}

/// The file `record start FILE` names.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordFile {
    /// As typed.
    pub name: String,
    pub span: Span,
    /// `overwrite`: an existing file of that name is replaced (else it is
    /// refused).
    pub overwrite: bool,
}

impl Record {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<Record, LangError> {
        let record = if a.is_empty() {
            Record::Status
        } else if a.keyword("start") {
            match a.peek() {
                Some(_) => {
                    let file = a.next("file")?;
                    Record::Start(Some(RecordFile {
                        name: file.text.clone(),
                        span: file.span,
                        overwrite: a.keyword("overwrite"),
                    }))
                }
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
                    (Some(f), _) => f.target(ctx)?,
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

impl RecordFile {
    /// Where this session may record under this name: the path checked
    /// against the session's file access, new unless `overwrite`.
    fn target(&self, ctx: &Context) -> Result<RecordTarget, LangError> {
        let path = ctx
            .files
            .recording(&self.name, ctx.record_dir.as_deref())
            .map_err(|e| LangError::new(self.span, e))?;
        if self.overwrite {
            return Ok(RecordTarget::File(path));
        }
        // Said here for a clear message; the recorder creates the file
        // exclusively all the same, so one appearing meanwhile is refused.
        if path.symlink_metadata().is_ok() {
            return Err(LangError::new(
                self.span,
                format!(
                    "{} exists: record to a new name, or add `overwrite` to replace it",
                    path.display()
                ),
            ));
        }
        Ok(RecordTarget::NewFile(path))
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
