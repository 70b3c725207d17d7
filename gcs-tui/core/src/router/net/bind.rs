//! Binding the router's endpoints: one UDP socket per worker, all on the
//! same address (`SO_REUSEPORT`: the kernel spreads senders over the
//! group, each sender always to the same socket), and the TCP listener.

use std::net::SocketAddr;
use std::sync::Arc;

use crate::router::{RouterConfig, RouterError};

/// The bound endpoints, before any task runs on them.
#[derive(Debug)]
pub(in crate::router) struct Bound {
    /// One socket per UDP worker, all on `udp_addr`.
    pub(in crate::router) udp: Vec<Arc<std::net::UdpSocket>>,
    pub(in crate::router) udp_addr: SocketAddr,
    pub(in crate::router) tcp: Option<tokio::net::TcpListener>,
    pub(in crate::router) tcp_addr: Option<SocketAddr>,
}

/// Binds the configured endpoints: one UDP socket per worker, all on the
/// same address (`SO_REUSEPORT`), and the TCP listener.
pub(in crate::router) async fn bind(config: &RouterConfig) -> Result<Bound, RouterError> {
    let bind_err = |addr, source| RouterError::Bind {
        what: "UDP",
        addr,
        source,
    };
    // The group's sockets share their port with any socket that asks
    // (`SO_REUSEPORT`), a second station's included, which would then
    // receive part of this one's traffic. A plain socket binds only a free
    // port: if it cannot, another program (or station) has it. Asked for
    // port 0, the kernel would hand a socket of a new group a port an
    // existing group of the same user holds (such ports count as free to
    // share), so the port is picked by a plain socket too.
    let probe = || {
        let probe = std::net::UdpSocket::bind(config.udp)?;
        probe.local_addr()
    };
    let udp = bind_group(config, probe).map_err(|(addr, e)| bind_err(addr, e))?;
    let udp_addr = local_addr("UDP", config.udp, udp[0].local_addr())?;
    let tcp = match config.tcp {
        Some(addr) => Some(
            tokio::net::TcpListener::bind(addr)
                .await
                .map_err(|source| RouterError::Bind {
                    what: "TCP",
                    addr,
                    source,
                })?,
        ),
        None => None,
    };
    let tcp_addr = match (&tcp, config.tcp) {
        (Some(l), Some(asked)) => Some(local_addr("TCP", asked, l.local_addr())?),
        _ => None,
    };
    Ok(Bound {
        udp,
        udp_addr,
        tcp,
        tcp_addr,
    })
}

/// Attempts at a free port when any port will do (see [`bind_group`]).
const PICKS: usize = 8;

/// Binds the UDP group on the address `pick` returns: the configured
/// address, or, asked for port 0, a port a plain socket found free. That
/// socket is closed before the group binds, and on a busy host another
/// program may bind the port in between; the group then picks again (up to
/// [`PICKS`] times) rather than fail a station that asked for any port.
fn bind_group(
    config: &RouterConfig,
    mut pick: impl FnMut() -> std::io::Result<SocketAddr>,
) -> Result<Vec<Arc<std::net::UdpSocket>>, (SocketAddr, std::io::Error)> {
    let any_port = config.udp.port() == 0;
    let mut attempt = 0;
    loop {
        attempt += 1;
        let addr = pick().map_err(|e| (config.udp, e))?;
        let mut udp = Vec::with_capacity(config.udp_workers.max(1));
        let mut taken = None;
        for _ in 0..config.udp_workers.max(1) {
            match bind_udp(addr, config.socket_buffer) {
                Ok(s) => udp.push(Arc::new(s)),
                Err(e) => {
                    taken = Some(e);
                    break;
                }
            }
        }
        match taken {
            None => return Ok(udp),
            Some(e)
                if any_port
                    && udp.is_empty()
                    && e.kind() == std::io::ErrorKind::AddrInUse
                    && attempt < PICKS =>
            {
                tracing::debug!(%addr, attempt, "the picked port was taken before the router bound it; picking again");
            }
            Some(e) => return Err((addr, e)),
        }
    }
}

/// The address an endpoint was bound to (the port, when 0 was asked for).
fn local_addr(
    what: &'static str,
    asked: SocketAddr,
    bound: std::io::Result<SocketAddr>,
) -> Result<SocketAddr, RouterError> {
    bound.map_err(|source| RouterError::Bind {
        what,
        addr: asked,
        source,
    })
}

/// Binds one of the router's UDP sockets, with `SO_REUSEPORT` and large
/// kernel buffers (best effort: a smaller system limit is logged, not
/// fatal).
fn bind_udp(addr: SocketAddr, buffer: usize) -> std::io::Result<std::net::UdpSocket> {
    use socket2::{Domain, Protocol, Socket, Type};
    let socket = Socket::new(Domain::for_address(addr), Type::DGRAM, Some(Protocol::UDP))?;
    socket.set_reuse_port(true)?;
    if let Err(e) = socket.set_recv_buffer_size(buffer) {
        tracing::warn!(error = %e, buffer, "cannot enlarge the UDP receive buffer");
    }
    if let Err(e) = socket.set_send_buffer_size(buffer) {
        tracing::warn!(error = %e, buffer, "cannot enlarge the UDP send buffer");
    }
    // Blocking, read by its worker thread with no timeout (a timed wait
    // costs a timer per datagram); shutdown wakes it.
    socket.bind(&addr.into())?;
    Ok(socket.into())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Stations asking for any port get one each: a second station never
    /// joins the first one's `SO_REUSEPORT` group (it would receive part of
    /// the first one's traffic). Bound with `SO_REUSEPORT` from the start,
    /// 600 groups on one host share a port (about 6 pairs, by the birthday
    /// bound over the ephemeral range) far more often than not.
    #[tokio::test]
    async fn stations_on_port_0_never_share_a_port() {
        let config = RouterConfig {
            udp: "127.0.0.1:0".parse().unwrap(),
            tcp: None,
            udp_workers: 1,
            socket_buffer: 4096,
            ..RouterConfig::default()
        };
        let mut held = Vec::new();
        let mut ports = std::collections::HashSet::new();
        for _ in 0..600 {
            let bound = bind(&config).await.unwrap();
            let port = bound.udp[0].local_addr().unwrap().port();
            assert!(ports.insert(port), "port {port} given to two stations");
            held.push(bound.udp);
        }
    }

    /// A port another program binds between the pick and the group's bind
    /// (a suite on a busy host: the pick's socket is closed first) makes the
    /// group pick again; a configured port that is taken is an error.
    #[test]
    fn a_picked_port_taken_before_the_bind_is_picked_again() {
        let thief = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let taken = thief.local_addr().unwrap();
        let config = RouterConfig {
            udp: "127.0.0.1:0".parse().unwrap(),
            tcp: None,
            udp_workers: 2,
            socket_buffer: 4096,
            ..RouterConfig::default()
        };
        let mut picks = 0;
        let udp = bind_group(&config, || {
            picks += 1;
            if picks == 1 {
                Ok(taken)
            } else {
                let probe = std::net::UdpSocket::bind("127.0.0.1:0")?;
                probe.local_addr()
            }
        })
        .unwrap();
        assert_eq!(picks, 2);
        assert_eq!(udp.len(), 2);
        assert_ne!(udp[0].local_addr().unwrap(), taken);
        assert_eq!(
            udp[0].local_addr().unwrap(),
            udp[1].local_addr().unwrap(),
            "one group"
        );

        let fixed = RouterConfig {
            udp: taken,
            ..config
        };
        let (addr, e) = bind_group(&fixed, || Ok(taken)).unwrap_err();
        assert_eq!((addr, e.kind()), (taken, std::io::ErrorKind::AddrInUse));
    }
}
