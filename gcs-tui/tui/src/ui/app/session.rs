//! This TUI's session: the station's router it shows, the station it is
//! attached to (none when it runs its own), the operator it speaks as, and
//! how it draws and listens (colours, the mouse). Set when the TUI starts.

/// Whom this TUI speaks for and how.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Session {
    /// The station's router address, shown in the status bar.
    pub router_addr: String,
    /// Who the station logs this TUI's commands under.
    pub operator: String,
    /// The station this TUI is attached to (`gcs.sock`, `host:7701`); None
    /// when it runs its own station (embedded).
    pub attached: Option<String>,
    /// Draw with modifiers only, no colours.
    pub monochrome: bool,
    /// Mouse events are taken (off with `--no-mouse`).
    pub mouse: bool,
}

impl Session {
    /// An embedded session on `router_addr`, in colour, with the mouse.
    pub fn new(router_addr: impl Into<String>) -> Session {
        Session {
            router_addr: router_addr.into(),
            operator: String::new(),
            attached: None,
            monochrome: false,
            mouse: true,
        }
    }
}
