//! UDP to the GCS router, the default link: one message per datagram,
//! datagrams from anyone but the router ignored. The agent's async loop uses
//! tokio's socket ([`crate::runtime::Io::Udp`]); this blocking
//! [`DatagramLink`] serves tools and tests that step an agent by hand.

use std::net::{SocketAddr, UdpSocket};

use crate::hal::{DatagramLink, ErrorType};

/// The default router address (the GCS's default UDP port on this machine).
pub const DEFAULT_ROUTER: &str = "127.0.0.1:7400";

/// A non-blocking UDP socket bound to talk with one router.
#[derive(Debug)]
pub struct UdpLink {
    socket: UdpSocket,
    router: SocketAddr,
}

impl UdpLink {
    /// Binds `local` (e.g. `0.0.0.0:0`) and talks to `router`.
    pub fn bind(local: SocketAddr, router: SocketAddr) -> std::io::Result<UdpLink> {
        let socket = UdpSocket::bind(local)?;
        socket.set_nonblocking(true)?;
        Ok(UdpLink { socket, router })
    }

    pub fn local_addr(&self) -> std::io::Result<SocketAddr> {
        self.socket.local_addr()
    }
}

impl ErrorType for UdpLink {
    type Error = std::io::Error;
}

impl DatagramLink for UdpLink {
    fn send(&mut self, datagram: &[u8]) -> std::io::Result<()> {
        self.socket.send_to(datagram, self.router).map(|_| ())
    }

    fn try_recv(&mut self, buf: &mut [u8]) -> std::io::Result<Option<usize>> {
        loop {
            match self.socket.recv_from(buf) {
                Ok((n, from)) if from == self.router => return Ok(Some(n)),
                Ok(_) => continue,
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => return Ok(None),
                Err(e) => return Err(e),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn talks_only_to_its_router() {
        let router = UdpSocket::bind("127.0.0.1:0").unwrap();
        let stranger = UdpSocket::bind("127.0.0.1:0").unwrap();
        let mut link =
            UdpLink::bind("127.0.0.1:0".parse().unwrap(), router.local_addr().unwrap()).unwrap();
        let me = link.local_addr().unwrap();
        link.send(b"hello").unwrap();
        let mut buf = [0; 16];
        let (n, from) = router.recv_from(&mut buf).unwrap();
        assert_eq!((&buf[..n], from), (&b"hello"[..], me));
        stranger.send_to(b"spoof", me).unwrap();
        router.send_to(b"route", me).unwrap();
        let mut got = None;
        for _ in 0..1000 {
            if let Some(n) = link.try_recv(&mut buf).unwrap() {
                got = Some(buf[..n].to_vec());
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        assert_eq!(got.as_deref(), Some(&b"route"[..]));
    }
}
