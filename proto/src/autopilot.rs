//! What a robot's notices say of its autopilot (PX4, ArduPilot): the texts
//! a robot flown by one sends when the autopilot is found, is armed or
//! disarmed, changes mode, or goes silent, and reading them back. The
//! station keeps each robot's armed state and flight mode from them
//! (`docs/protocol.md`, *Autopilots*); the texts are also what an operator
//! reads in the event log, so they stay plain sentences.

/// One fact about a robot's autopilot, as a notice's text carries it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum AutopilotNews {
    /// The autopilot was heard for the first time (`autopilot found: PX4
    /// MAV_TYPE_QUADROTOR, system 1 component 1`); the text after the
    /// colon says which.
    Found(String),
    /// `autopilot armed` / `autopilot disarmed`.
    Armed(bool),
    /// `autopilot mode OFFBOARD`: the flight mode by the firmware's name.
    Mode(String),
    /// `autopilot lost: ...`: its heartbeat stopped.
    Lost(String),
    /// `autopilot heard again`.
    HeardAgain,
}

const FOUND: &str = "autopilot found: ";
const MODE: &str = "autopilot mode ";
const LOST: &str = "autopilot lost";
const ARMED: &str = "autopilot armed";
const DISARMED: &str = "autopilot disarmed";
const HEARD_AGAIN: &str = "autopilot heard again";

impl AutopilotNews {
    /// The notice text.
    pub fn text(&self) -> String {
        match self {
            AutopilotNews::Found(which) => format!("{FOUND}{which}"),
            AutopilotNews::Armed(true) => ARMED.to_string(),
            AutopilotNews::Armed(false) => DISARMED.to_string(),
            AutopilotNews::Mode(mode) => format!("{MODE}{mode}"),
            AutopilotNews::Lost(why) if why.is_empty() => LOST.to_string(),
            AutopilotNews::Lost(why) => format!("{LOST}: {why}"),
            AutopilotNews::HeardAgain => HEARD_AGAIN.to_string(),
        }
    }

    /// What a notice's text says of the autopilot, if anything (other
    /// notices, `arm sent to the autopilot` for one, are not news of its
    /// state).
    pub fn parse(text: &str) -> Option<AutopilotNews> {
        if let Some(which) = text.strip_prefix(FOUND) {
            return Some(AutopilotNews::Found(which.to_string()));
        }
        if let Some(mode) = text.strip_prefix(MODE) {
            return (!mode.is_empty()).then(|| AutopilotNews::Mode(mode.to_string()));
        }
        if let Some(rest) = text.strip_prefix(LOST) {
            let why = rest.strip_prefix(": ").unwrap_or(rest);
            return (rest.is_empty() || rest.starts_with(": "))
                .then(|| AutopilotNews::Lost(why.to_string()));
        }
        match text {
            ARMED => Some(AutopilotNews::Armed(true)),
            DISARMED => Some(AutopilotNews::Armed(false)),
            HEARD_AGAIN => Some(AutopilotNews::HeardAgain),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_fact_reads_back_from_its_text() {
        let all = [
            AutopilotNews::Found("PX4 MAV_TYPE_QUADROTOR, system 1 component 1".into()),
            AutopilotNews::Armed(true),
            AutopilotNews::Armed(false),
            AutopilotNews::Mode("OFFBOARD".into()),
            AutopilotNews::Mode("PX4 3.0".into()),
            AutopilotNews::Lost("no heartbeat for 2.0 s".into()),
            AutopilotNews::Lost(String::new()),
            AutopilotNews::HeardAgain,
        ];
        for news in all {
            assert_eq!(AutopilotNews::parse(&news.text()), Some(news.clone()));
        }
        assert_eq!(AutopilotNews::Armed(true).text(), "autopilot armed");
        assert_eq!(
            AutopilotNews::Mode("GUIDED".into()).text(),
            "autopilot mode GUIDED"
        );
    }

    #[test]
    fn other_notices_are_not_news_of_the_autopilot() {
        for text in [
            "arm sent to the autopilot",
            "autopilot accepted arm",
            "autopilot refused arm: MAV_RESULT_DENIED",
            "autopilot: PREFLIGHT FAIL",
            "autopilot mode ",
            "autopilot lostness",
            "left wheel stalled",
        ] {
            assert_eq!(AutopilotNews::parse(text), None, "{text}");
        }
    }
}
