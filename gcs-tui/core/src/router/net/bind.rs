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
    let addr = {
        let probe = std::net::UdpSocket::bind(config.udp).map_err(|e| bind_err(config.udp, e))?;
        probe.local_addr().map_err(|e| bind_err(config.udp, e))?
    };
    let mut udp = Vec::with_capacity(config.udp_workers.max(1));
    for _ in 0..config.udp_workers.max(1) {
        let s = bind_udp(addr, config.socket_buffer).map_err(|e| bind_err(addr, e))?;
        udp.push(Arc::new(s));
    }
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
}
