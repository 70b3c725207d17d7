//! Attaching to a station: over its control socket, over TCP with an
//! operator key, or in process (the embedded station); and running a
//! script against it (`mech-gcs --attach ADDR --script FILE`).

use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

use mech_control::lang::{LangError, Outcome, Span, Statement, parse_script};
use mech_control::script::{ScriptOutcome, result_json_at};
use mech_core::auth::KeyFile;
use serde_json::{Value, json};
use tokio::io::{AsyncRead, AsyncWrite, AsyncWriteExt, BufReader};
use tokio::sync::mpsc;

use crate::wire::{
    FromStation, LineResult, MAX_LINE, PROTOCOL, Streams, ToStation, Welcome, challenge_region,
    hex, read_message, to_line, unhex,
};

/// Time the station has to answer the Hello.
const HANDSHAKE: Duration = Duration::from_secs(10);

/// Messages from the station waiting for the client.
const INBOX: usize = 1024;

/// Where a station listens.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Address {
    /// A control socket.
    Unix(PathBuf),
    /// `host:port` of a station's TCP endpoint.
    Tcp(String),
}

impl Address {
    /// `tcp:HOST:PORT` or `HOST:PORT` is TCP; `unix:PATH` or anything with
    /// a `/` (or no `:`) is a socket path.
    pub fn parse(text: &str) -> Address {
        if let Some(rest) = text.strip_prefix("tcp:") {
            return Address::Tcp(rest.to_string());
        }
        if let Some(rest) = text.strip_prefix("unix:") {
            return Address::Unix(rest.into());
        }
        if text.contains('/') || !text.contains(':') {
            Address::Unix(text.into())
        } else {
            Address::Tcp(text.to_string())
        }
    }
}

impl std::fmt::Display for Address {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Address::Unix(p) => write!(f, "{}", p.display()),
            Address::Tcp(a) => write!(f, "tcp:{a}"),
        }
    }
}

impl Address {
    /// The address as a status bar names it: a socket's file name
    /// (`gcs.sock`), a TCP address as given (`host:7701`).
    pub fn short(&self) -> String {
        match self {
            Address::Unix(p) => p.file_name().map_or_else(
                || p.display().to_string(),
                |n| n.to_string_lossy().into_owned(),
            ),
            Address::Tcp(a) => a.clone(),
        }
    }
}

/// Why attaching failed.
#[derive(Debug, thiserror::Error)]
pub enum AttachError {
    #[error("cannot reach the station at {addr}: {source}")]
    Connect {
        addr: String,
        source: std::io::Error,
    },
    #[error(
        "will not attach through {path}: {why}; whoever may write there could have put their \
         own socket in the station's place"
    )]
    UnsafeSocket { path: PathBuf, why: String },
    #[error("the station asks for an operator key: give one with --key FILE")]
    NeedKey,
    #[error("the station refused: {0}")]
    Refused(String),
    #[error("the station did not answer in time")]
    Timeout,
    #[error("the station closed the connection")]
    Closed,
    #[error("unexpected answer from the station: {0}")]
    Protocol(String),
}

/// Who attaches and what it wants.
#[derive(Debug, Clone, Default)]
pub struct AttachOptions {
    /// The operator's name (a label on a local socket; over TCP the key's
    /// name is used).
    pub operator: Option<String>,
    /// The operator key, for a station's TCP endpoint.
    pub key: Option<KeyFileRef>,
    pub stream: Streams,
}

/// An operator key, by value (keys are not `Clone`-cheap to re-read).
#[derive(Debug, Clone)]
pub struct KeyFileRef {
    pub name: String,
    pub key: mech_proto::auth::Key,
}

impl From<KeyFile> for KeyFileRef {
    fn from(k: KeyFile) -> Self {
        KeyFileRef {
            name: k.name,
            key: k.key,
        }
    }
}

/// An attached client: what the station said on attaching, a sender for
/// messages to it and a receiver of everything it sends. The connection
/// ends when both are dropped, or when the station leaves (the receiver
/// then ends).
#[derive(Debug)]
pub struct Attached {
    pub welcome: Welcome,
    pub to: mpsc::UnboundedSender<ToStation>,
    pub from: mpsc::Receiver<FromStation>,
}

/// Attaches to the station at `addr`.
pub async fn attach(addr: &Address, opts: AttachOptions) -> Result<Attached, AttachError> {
    let connect_err = |source| AttachError::Connect {
        addr: addr.to_string(),
        source,
    };
    match addr {
        Address::Unix(path) => {
            check_socket(path)?;
            let s = tokio::net::UnixStream::connect(path)
                .await
                .map_err(connect_err)?;
            attach_stream(s, opts).await
        }
        Address::Tcp(host) => {
            let s = tokio::net::TcpStream::connect(host.as_str())
                .await
                .map_err(connect_err)?;
            let _ = s.set_nodelay(true);
            attach_stream(s, opts).await
        }
    }
}

/// Checks a control socket's directory before attaching through it: it
/// must be writable by nobody but its owner, and the default socket's
/// (`$XDG_RUNTIME_DIR/mech`, `/tmp/mech-UID`) must be this user's own, as
/// the station that made it was. A missing directory is left for the
/// connection to report.
fn check_socket(path: &std::path::Path) -> Result<(), AttachError> {
    let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) else {
        return Ok(());
    };
    if std::fs::symlink_metadata(dir).is_err() {
        return Ok(());
    }
    let owner = (path == crate::default_socket()).then(|| nix::unistd::geteuid().as_raw());
    crate::listen::check_socket_dir(dir, owner).map_err(|why| AttachError::UnsafeSocket {
        path: dir.to_owned(),
        why,
    })
}

/// Attaches over an open stream (a socket, or the embedded station's
/// [`crate::Station::attach_local`] pipe).
pub async fn attach_stream<S>(stream: S, opts: AttachOptions) -> Result<Attached, AttachError>
where
    S: AsyncRead + AsyncWrite + Send + 'static,
{
    let (rd, mut wr) = tokio::io::split(stream);
    let mut rd = BufReader::new(rd);
    let welcome = tokio::time::timeout(HANDSHAKE, handshake(&mut rd, &mut wr, &opts))
        .await
        .map_err(|_| AttachError::Timeout)??;
    let (to, mut outbox) = mpsc::unbounded_channel::<ToStation>();
    let (inbox, from) = mpsc::channel(INBOX);
    tokio::spawn(async move {
        while let Some(m) = outbox.recv().await {
            if wr.write_all(to_line(&m).as_bytes()).await.is_err() {
                return;
            }
        }
        let _ = wr.write_all(to_line(&ToStation::Bye).as_bytes()).await;
        let _ = wr.shutdown().await;
    });
    tokio::spawn(async move {
        let mut buf = Vec::new();
        while let Ok(Some(m)) = read_message::<FromStation>(&mut rd, &mut buf, MAX_LINE).await {
            if inbox.send(m).await.is_err() {
                return;
            }
        }
    });
    Ok(Attached { welcome, to, from })
}

async fn handshake<R, W>(
    rd: &mut BufReader<R>,
    wr: &mut W,
    opts: &AttachOptions,
) -> Result<Welcome, AttachError>
where
    R: AsyncRead + Unpin,
    W: AsyncWrite + Unpin,
{
    let hello = ToStation::Hello {
        protocol: PROTOCOL,
        operator: opts.operator.clone(),
        stream: opts.stream,
    };
    send(wr, &hello).await?;
    let mut buf = Vec::new();
    loop {
        let m = read_message::<FromStation>(rd, &mut buf, MAX_LINE)
            .await
            .map_err(|e| AttachError::Protocol(e.to_string()))?
            .ok_or(AttachError::Closed)?;
        match m {
            FromStation::Welcome(w) => return Ok(w),
            FromStation::Challenge { nonce } => {
                let key = opts.key.as_ref().ok_or(AttachError::NeedKey)?;
                let nonce = unhex(&nonce)
                    .ok_or_else(|| AttachError::Protocol("the challenge is not hex".into()))?;
                let tag = key.key.sign(&challenge_region(&nonce, &key.name), 0, 0);
                send(wr, &ToStation::Auth { tag: hex(&tag) }).await?;
            }
            FromStation::Bye { reason } => return Err(AttachError::Refused(reason)),
            other => return Err(AttachError::Protocol(format!("{other:?}"))),
        }
    }
}

async fn send<W: AsyncWrite + Unpin>(wr: &mut W, m: &ToStation) -> Result<(), AttachError> {
    wr.write_all(to_line(m).as_bytes())
        .await
        .map_err(|_| AttachError::Closed)
}

/// Runs `source` on an attached station (which must stream events),
/// printing the JSON lines `--script` prints; returns how it ended.
pub async fn run_script(
    attached: &mut Attached,
    source: &str,
    out: &mut dyn Write,
) -> ScriptOutcome {
    let statements = match parse_script(source) {
        Ok(s) => s,
        Err(e) => {
            emit(
                out,
                &json!({"type": "summary", "ok": false, "commands": 0, "error": e.to_string()}),
            );
            return ScriptOutcome::Invalid(e);
        }
    };
    let mut outcome = ScriptOutcome::Passed {
        commands: statements.len(),
    };
    for (i, stmt) in statements.iter().enumerate() {
        let id = i as u64 + 1;
        let result = run_line(attached, id, stmt, out).await;
        if let Err(error) = result {
            outcome = ScriptOutcome::Failed {
                error,
                commands: i + 1,
            };
            break;
        }
    }
    let (ok, ran, error) = match &outcome {
        ScriptOutcome::Passed { commands } => (true, *commands, None),
        ScriptOutcome::Failed { error, commands } => (false, *commands, Some(error.to_string())),
        ScriptOutcome::Invalid(e) => (false, 0, Some(e.to_string())),
    };
    emit(
        out,
        &json!({"type": "summary", "ok": ok, "commands": ran, "error": error,
                "operator": attached.welcome.operator, "router": attached.welcome.router}),
    );
    outcome
}

/// Sends one statement and prints what comes back until its result.
async fn run_line(
    attached: &mut Attached,
    id: u64,
    stmt: &Statement,
    out: &mut dyn Write,
) -> Result<(), LangError> {
    let lost = |what: &str| LangError::new(stmt.span, format!("the station {what}"));
    let line = ToStation::Line {
        id,
        text: stmt.text.clone(),
    };
    attached.to.send(line).map_err(|_| lost("is gone"))?;
    loop {
        match attached.from.recv().await {
            None => return Err(lost("closed the connection")),
            Some(FromStation::Bye { reason }) => return Err(lost(&format!("left: {reason}"))),
            Some(FromStation::Event(mut m)) => {
                m.insert("type".into(), json!("event"));
                emit(out, &Value::Object(m));
            }
            Some(FromStation::Result(r)) if r.id == id => {
                let (t, result) = local_result(stmt, r);
                emit(out, &result_json_at(t, stmt, result.as_ref()));
                return result.map(|_| ());
            }
            Some(FromStation::Refused { reason }) => {
                emit(out, &json!({"type": "refused", "reason": reason}));
            }
            Some(_) => {}
        }
    }
}

/// A station's result as the local statement's outcome (errors point at
/// the script's line).
fn local_result(stmt: &Statement, r: LineResult) -> (f64, Result<Outcome, LangError>) {
    let result = if r.ok {
        Ok(Outcome {
            summary: r.summary,
            details: r.details,
        })
    } else {
        // The station read the statement's text alone: its columns count
        // from the statement's first word.
        let span = Span {
            line: stmt.span.line,
            column: r
                .column
                .map_or(stmt.span.column, |c| stmt.span.column + c.saturating_sub(1)),
        };
        Err(LangError::new(span, r.error.unwrap_or_default()))
    };
    (r.t, result)
}

fn emit(out: &mut dyn Write, v: &Value) {
    // Output is best effort: a closed stdout must not stop the script.
    let _ = writeln!(out, "{v}");
    let _ = out.flush();
}
