//! Live channels: every channel something was published on, its last
//! publisher, its rate and traffic; the listing for `channels()` and for
//! channel discovery (`ChannelsRequest`). A channel is live while it was
//! published on within `channel_live_for`. At most [`CHANNELS`] are kept:
//! a new one past that takes the place of the one silent longest.

use std::collections::{BTreeMap, HashMap};

use mech_proto::{Body, Channels as ChannelsBody};
use tokio::time::Instant;
use tracing::info;

use super::traffic::Tally;
use super::{Ctx, Delivery, Incoming, Tables};
use crate::counters::{ChannelStatus, Traffic};
use crate::event::Event;
use crate::router::rate::RateMeter;

/// Most channels kept. Channels are names publishers choose, so the table
/// would otherwise grow with every name ever used (and each listing and
/// counters read copies it whole).
pub(super) const CHANNELS: usize = 1024;

/// Every channel published on, by name.
#[derive(Debug, Default)]
pub(super) struct Channels {
    by_name: HashMap<String, ChannelEntry>,
}

#[derive(Debug)]
struct ChannelEntry {
    publisher: String,
    last: Instant,
    rate: RateMeter,
    traffic: Tally,
}

impl Channels {
    /// Counts a message published on `channel` by `sender`; `true` if the
    /// channel is new or has a new publisher.
    fn note(&mut self, sender: &str, channel: &str, now: Instant) -> bool {
        match self.by_name.get_mut(channel) {
            Some(c) => {
                c.traffic.heard();
                c.last = now;
                c.rate.record(now);
                if c.publisher == sender {
                    return false;
                }
                c.publisher.clear();
                c.publisher.push_str(sender);
                true
            }
            None => {
                let mut rate = RateMeter::new(now);
                rate.record(now);
                let entry = ChannelEntry {
                    publisher: sender.to_string(),
                    last: now,
                    rate,
                    traffic: Tally::first(),
                };
                if self.by_name.len() >= CHANNELS {
                    let silent = self.by_name.iter().min_by_key(|(_, c)| c.last);
                    if let Some(name) = silent.map(|(n, _)| n.clone()) {
                        self.by_name.remove(&name);
                    }
                }
                self.by_name.insert(channel.to_string(), entry);
                true
            }
        }
    }

    /// The counts of `channel`, if anything was published on it.
    pub(super) fn tally_mut(&mut self, channel: &str) -> Option<&mut Tally> {
        self.by_name.get_mut(channel).map(|c| &mut c.traffic)
    }

    #[cfg(test)]
    pub(super) fn len(&self) -> usize {
        self.by_name.len()
    }

    #[cfg(test)]
    pub(super) fn contains(&self, channel: &str) -> bool {
        self.by_name.contains_key(channel)
    }

    /// Each channel's traffic counters.
    pub(super) fn traffic(&self) -> BTreeMap<String, Traffic> {
        self.by_name
            .iter()
            .map(|(n, c)| (n.clone(), c.traffic.traffic()))
            .collect()
    }
}

impl Tables {
    /// Counts a message published on `channel` and remembers its publisher.
    pub(super) fn note_publisher(&mut self, sender: &str, channel: &str, cx: &mut Ctx<'_>) {
        if channel.is_empty() || !self.channels.note(sender, channel, cx.now) {
            return;
        }
        info!(channel, publisher = sender, from = %cx.from, "channel publisher");
        cx.event(Event::ChannelPublisher {
            channel: channel.to_string(),
            publisher: sender.to_string(),
        });
    }

    pub(super) fn on_channels_request(&mut self, m: Incoming<'_>, cx: &mut Ctx<'_>) -> Delivery {
        let channels = self
            .channel_status(cx.now)
            .into_iter()
            .map(|c| mech_proto::ChannelInfo {
                name: c.name,
                publisher: c.publisher,
                rate_hz: c.rate_hz,
                robots: c.robots,
                idle_ms: c.idle.as_millis() as u64,
            })
            .collect();
        let body = Body::Channels(ChannelsBody { channels });
        if let Some(b) = self.make(&m.header.sender, body) {
            cx.send(cx.from, b);
        }
        Delivery::Consumed
    }

    /// Live channels (published within `channel_live_for`), by name, with
    /// the robots routed to each.
    pub(crate) fn channel_status(&self, now: Instant) -> Vec<ChannelStatus> {
        let live_for = self.config.channel_live_for;
        let mut list: Vec<ChannelStatus> = self
            .channels
            .by_name
            .iter()
            .filter(|(_, c)| now.saturating_duration_since(c.last) < live_for)
            .map(|(name, c)| {
                let mut robots: Vec<String> = self
                    .robots
                    .iter()
                    .filter(|(_, r)| r.route.is(name))
                    .map(|(n, _)| n.clone())
                    .collect();
                robots.sort();
                ChannelStatus {
                    name: name.clone(),
                    publisher: c.publisher.clone(),
                    rate_hz: c.rate.rate_hz(now),
                    robots,
                    idle: now.saturating_duration_since(c.last),
                }
            })
            .collect();
        list.sort_by(|a, b| a.name.cmp(&b.name));
        list
    }
}
