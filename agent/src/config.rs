//! The robot's TOML configuration: name, platform and geometry, drivers and
//! pins, link, failsafe, filter, control gains, wheel encoders and the
//! simulated start pose.
//!
//! Errors name the file, line and column and say what was expected, using
//! the `toml` crate's spans.

use std::net::SocketAddr;
use std::ops::Range;
use std::path::Path;
use std::time::Duration;

use serde::Deserialize;
use toml::Spanned;

use crate::control::Gains;
use crate::drivers::edge_counter::EncoderPins;
use crate::drivers::l298::{DutyRange, L298Pins};
use crate::failsafe::{FailsafeConfig, FailsafeToml};
use crate::fusion::FusionSettings;
use crate::hal::Counting;
use crate::machine::AgentSettings;
use crate::platform::PlatformSpec;
use crate::wheels::{PiGains, StallSettings, WheelSettings};

/// A whole robot config file.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotConfig {
    /// Robot name, unique in the fleet (no spaces).
    pub name: Spanned<String>,
    #[serde(default = "default_control_rate")]
    pub control_rate_hz: Spanned<f64>,
    #[serde(default = "default_telemetry_rate")]
    pub telemetry_rate_hz: Spanned<f64>,
    /// Answer commands from unrouted channels with a `NotRouted` notice.
    #[serde(default = "yes")]
    pub notify_not_routed: bool,
    pub platform: Spanned<Kind<PlatformSpec>>,
    #[serde(default = "spanned_default")]
    pub link: Spanned<Kind<LinkConfig>>,
    /// Several links to the router (`[[links]]`, instead of `[link]`), in
    /// order of preference: the robot uses the first that is alive and
    /// fails over to the next (Wi-Fi first, then a radio).
    #[serde(default)]
    pub links: Vec<Spanned<Kind<LinkConfig>>>,
    /// `[failover]`: when a link counts as alive.
    #[serde(default)]
    pub failover: FailoverConfig,
    #[serde(default = "spanned_default")]
    pub failsafe: Spanned<FailsafeToml>,
    #[serde(default = "spanned_default")]
    pub actuators: Spanned<Kind<ActuatorConfig>>,
    #[serde(default = "spanned_default")]
    pub position: Spanned<Kind<PositionConfig>>,
    #[serde(default = "spanned_default")]
    pub filter: Spanned<FilterConfig>,
    #[serde(default)]
    pub control: Gains,
    #[serde(default)]
    pub sim: SimConfig,
    /// `[auth]`: the robot's key (`mech-gcs keygen NAME`); without it the
    /// robot runs unsigned and only an unauthenticated station accepts it.
    #[serde(default)]
    pub auth: Option<AuthConfig>,
    /// `[encoders]`: wheel encoders, for measured velocity, closed-loop
    /// wheel speed, stall detection and odometry between position fixes.
    #[serde(default)]
    pub encoders: Option<Spanned<EncoderConfig>>,
    /// `[autopilot]`: a PX4 or ArduPilot autopilot flies the vehicle
    /// (`docs/autopilots.md`); it then also gives the position.
    #[serde(default)]
    pub autopilot: Option<Spanned<crate::autopilot::AutopilotConfig>>,
    /// `[ros2]`: a ROS 2 mobile base drives the vehicle (`docs/ros2.md`);
    /// its odometry then also gives the position.
    #[serde(default)]
    pub ros2: Option<Spanned<crate::ros2_base::Ros2Config>>,
    /// `[safety]`: the robot's footprint and braking for the fleet safety
    /// layer (`docs/safety.md`), which the station's arena switches on.
    #[serde(default = "spanned_default")]
    pub safety: Spanned<crate::safety::SafetyConfig>,
}

/// `[auth]`: signing and checking with the router.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AuthConfig {
    /// The key file, private to the robot's user (relative paths are from
    /// the config file's folder).
    pub key: std::path::PathBuf,
    /// The router's sender name (its `router.name`).
    #[serde(default = "default_router_name")]
    pub router: String,
}

fn default_router_name() -> String {
    mech_proto::ROUTER.to_string()
}

fn default_control_rate() -> Spanned<f64> {
    Spanned::new(0..0, 50.0)
}

fn default_telemetry_rate() -> Spanned<f64> {
    Spanned::new(0..0, 20.0)
}

/// A defaulted section has an empty span (no place in the file).
fn spanned_default<T: Default>() -> Spanned<T> {
    Spanned::new(0..0, T::default())
}

fn yes() -> bool {
    true
}

/// `[link]`: how the agent reaches the router.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum LinkConfig {
    /// UDP datagrams to the router (default `127.0.0.1:7400`).
    Udp {
        #[serde(default = "default_router")]
        router: SocketAddr,
    },
    /// A serial radio (XBee transparent mode) or any UART.
    Serial {
        port: String,
        #[serde(default = "default_radio_baud")]
        baud: u32,
        /// Most telemetry messages per second sent over this link (the
        /// station shows each radio robot's budget); unset: the robot's
        /// `telemetry_rate_hz`.
        #[serde(default)]
        telemetry_rate_hz: Option<f64>,
    },
}

/// `[failover]`: for a robot with several links.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FailoverConfig {
    /// A link counts as alive while the router was heard on it within this
    /// (seconds); the router's heartbeat comes every 0.25 s on each link.
    pub link_timeout: f64,
    /// Period of the heartbeat sent on each link not in use, so the router
    /// knows it is there (seconds).
    pub probe_period: f64,
}

impl Default for FailoverConfig {
    fn default() -> Self {
        FailoverConfig {
            link_timeout: 0.6,
            probe_period: 0.25,
        }
    }
}

fn default_router() -> SocketAddr {
    SocketAddr::from(([127, 0, 0, 1], 7400))
}

fn default_radio_baud() -> u32 {
    57_600
}

impl Default for LinkConfig {
    fn default() -> Self {
        LinkConfig::Udp {
            router: default_router(),
        }
    }
}

/// `[actuators]`: the motor driver.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum ActuatorConfig {
    /// No motor driver (simulation, or a robot only reporting).
    #[default]
    None,
    /// L298 dual H-bridge on Raspberry Pi GPIO (feature `rpi`).
    L298 {
        /// One entry per motor, in the platform's motor order.
        channels: Vec<L298Pins>,
        #[serde(default = "default_pwm_frequency")]
        pwm_frequency: f64,
        #[serde(default = "default_min_duty")]
        min_duty: f64,
        #[serde(default = "default_max_duty")]
        max_duty: f64,
        #[serde(default = "default_deadband")]
        deadband: f64,
    },
}

fn default_pwm_frequency() -> f64 {
    100.0
}
fn default_min_duty() -> f64 {
    DutyRange::default().min_duty
}
fn default_max_duty() -> f64 {
    DutyRange::default().max_duty
}
fn default_deadband() -> f64 {
    DutyRange::default().deadband
}

/// `[position]`: where the robot's position comes from.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum PositionConfig {
    /// No position: velocity-heading and waypoints are not offered.
    #[default]
    None,
    /// The simulator: the agent runs a simulated vehicle (as with `--sim`).
    Sim,
    /// `PositionFix` messages relayed by the GCS (motion capture, an
    /// external tracker).
    External,
    /// A Pozyx UWB tag on a serial/USB port.
    Pozyx {
        port: String,
        #[serde(default = "default_pozyx_baud")]
        baud: u32,
        /// Added to the tag's heading so that 0 = arena +x, rad.
        #[serde(default)]
        heading_offset: f64,
    },
    /// An NMEA GPS receiver; positions in metres east/north of `origin`.
    Nmea {
        port: String,
        #[serde(default = "default_gps_baud")]
        baud: u32,
        origin: GeoOriginConfig,
    },
}

fn default_pozyx_baud() -> u32 {
    115_200
}
fn default_gps_baud() -> u32 {
    9_600
}

/// Geodetic origin of the local frame.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GeoOriginConfig {
    pub latitude: f64,
    pub longitude: f64,
    #[serde(default)]
    pub altitude: f64,
}

/// `[filter]`: the moving-median position filter.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FilterConfig {
    /// Samples in the median window (1 = no filtering).
    pub window: usize,
}

impl Default for FilterConfig {
    fn default() -> Self {
        FilterConfig { window: 9 }
    }
}

/// `[encoders]`: one encoder per wheel, in the platform's motor order.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EncoderConfig {
    /// `quadrature` (channels A and B) or `single-channel` (A only; the
    /// direction is taken from the commanded output).
    pub kind: Counting,
    /// BCM GPIO numbers of each wheel's channels, in motor order.
    pub channels: Vec<EncoderPins>,
    /// Edges counted per wheel revolution: every edge of every channel (a
    /// 360-line quadrature encoder gives 1440, a 20-slot disc on one
    /// channel 40), times the gear ratio if the encoder is on the motor.
    pub counts_per_revolution: f64,
    /// Wheel radius, m.
    pub wheel_radius: f64,
    /// Turn on the inputs' pull-up resistors (open-collector sensors).
    #[serde(default = "yes")]
    pub pull_up: bool,
    /// Close the wheel speed loop (PI per wheel); `false` only measures.
    #[serde(default = "yes")]
    pub closed_loop: bool,
    /// Speed loop gains, per unit of speed error as a fraction of
    /// `max_wheel_speed` (and per second for `ki`).
    #[serde(default = "default_kp")]
    pub kp: f64,
    #[serde(default = "default_ki")]
    pub ki: f64,
    /// Smallest output that must turn a wheel, fraction of full.
    #[serde(default = "default_stall_output")]
    pub stall_output: f64,
    /// Seconds such an output may give no edge before the wheel is stalled.
    #[serde(default = "default_stall_time")]
    pub stall_time: f64,
    /// Standard deviation of a position fix, m (the position source's
    /// accuracy; weighs fixes against odometry).
    #[serde(default = "default_position_sigma")]
    pub position_sigma: f64,
    /// Standard deviation of a measured heading, rad.
    #[serde(default = "default_heading_sigma")]
    pub heading_sigma: f64,
    /// Standard deviation of a wheel's travel as a fraction of it (slip,
    /// radius error).
    #[serde(default = "default_odometry_sigma")]
    pub odometry_sigma: f64,
}

fn default_kp() -> f64 {
    PiGains::default().kp
}
fn default_ki() -> f64 {
    PiGains::default().ki
}
fn default_stall_output() -> f64 {
    StallSettings::default().output
}
fn default_stall_time() -> f64 {
    StallSettings::default().time.as_secs_f64()
}
fn default_position_sigma() -> f64 {
    FusionSettings::default().position_sigma
}
fn default_heading_sigma() -> f64 {
    FusionSettings::default().heading_sigma
}
fn default_odometry_sigma() -> f64 {
    FusionSettings::default().odometry_sigma
}

impl EncoderConfig {
    /// The settings of the agent core's wheel layer.
    pub fn wheel_settings(&self) -> WheelSettings {
        WheelSettings {
            counting: self.kind,
            counts_per_revolution: self.counts_per_revolution,
            wheel_radius: self.wheel_radius,
            speed_loop: self.closed_loop.then_some(PiGains {
                kp: self.kp,
                ki: self.ki,
            }),
            stall: StallSettings {
                output: self.stall_output,
                time: Duration::from_secs_f64(self.stall_time),
            },
        }
    }

    /// The noise figures of the odometry fusion.
    pub fn fusion_settings(&self) -> FusionSettings {
        FusionSettings {
            position_sigma: self.position_sigma,
            heading_sigma: self.heading_sigma,
            odometry_sigma: self.odometry_sigma,
            ..FusionSettings::default()
        }
    }
}

/// `[sim]`: the simulated robot.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimConfig {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub heading: f64,
    /// UWB-like position noise.
    pub noise: bool,
    pub seed: u64,
}

impl Default for SimConfig {
    fn default() -> Self {
        SimConfig {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            heading: 0.0,
            noise: true,
            seed: 1,
        }
    }
}

/// A config that could not be used.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("{file}: cannot read: {error}")]
    Read { file: String, error: std::io::Error },
    #[error("{file}:{line}:{column}: {message}")]
    Invalid {
        file: String,
        line: usize,
        column: usize,
        message: String,
    },
}

impl RobotConfig {
    /// Reads and checks a config file.
    pub fn load(path: &Path) -> Result<RobotConfig, ConfigError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|error| ConfigError::Read {
            file: file.clone(),
            error,
        })?;
        let mut config = RobotConfig::parse(&text, &file)?;
        if let Some(auth) = config.auth.as_mut().filter(|a| a.key.is_relative()) {
            let dir = path.parent().unwrap_or(Path::new("."));
            auth.key = dir.join(&auth.key);
        }
        Ok(config)
    }

    /// The robot's key, read from its file: `None` without `[auth]`. The
    /// file must be private and hold this robot's key.
    pub fn key(&self) -> Result<Option<mech_proto::auth::Key>, String> {
        let Some(auth) = &self.auth else {
            return Ok(None);
        };
        let path = auth.key.display();
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let meta = std::fs::metadata(&auth.key).map_err(|e| format!("{path}: {e}"))?;
            mech_proto::auth::private_mode(meta.permissions().mode())
                .map_err(|e| format!("{path}: {e}"))?;
        }
        let text = std::fs::read_to_string(&auth.key).map_err(|e| format!("{path}: {e}"))?;
        let k = mech_proto::auth::KeyText::parse(&text).map_err(|e| format!("{path}: {e}"))?;
        if &k.name != self.name.get_ref() {
            return Err(format!(
                "{path} is the key of {:?}, not of this robot ({:?})",
                k.name,
                self.name.get_ref()
            ));
        }
        Ok(Some(k.key))
    }

    /// Parses and checks config text; `file` names it in errors.
    pub fn parse(text: &str, file: &str) -> Result<RobotConfig, ConfigError> {
        let invalid = |span: Option<Range<usize>>, message: String| {
            let (line, column) = span.map_or((1, 1), |s| {
                line_column(text, refine(text, s.start, &message))
            });
            ConfigError::Invalid {
                file: file.to_string(),
                line,
                column,
                message,
            }
        };
        let config: RobotConfig =
            toml::from_str(text).map_err(|e| invalid(e.span(), e.message().trim().to_string()))?;
        config
            .validate()
            .map_err(|(span, message)| invalid(span, message))?;
        Ok(config)
    }

    /// Semantic checks serde cannot express; errors carry the span of the
    /// offending value (or its table).
    fn validate(&self) -> Result<(), Problem> {
        check_name(self.name.get_ref()).map_err(|m| (at(self.name.span()), m))?;
        self.validate_rates()?;
        self.platform()
            .validate()
            .map_err(|m| (at(self.platform.span()), format!("[platform]: {m}")))?;
        self.validate_failsafe()?;
        self.validate_links()?;
        self.validate_filter()?;
        self.validate_actuators()?;
        self.validate_encoders()?;
        self.validate_vehicle()?;
        self.safety
            .get_ref()
            .validate()
            .map_err(|m| (at(self.safety.span()), format!("[safety]: {m}")))
    }

    fn validate_rates(&self) -> Result<(), Problem> {
        for (rate, what) in [
            (&self.control_rate_hz, "control_rate_hz"),
            (&self.telemetry_rate_hz, "telemetry_rate_hz"),
        ] {
            let v = *rate.get_ref();
            if !(v.is_finite() && v > 0.0 && v <= 1000.0) {
                return Err((
                    at(rate.span()),
                    format!("{what} = {v}: expected a rate in (0, 1000] Hz"),
                ));
            }
        }
        Ok(())
    }

    fn validate_failsafe(&self) -> Result<(), Problem> {
        let f = self.failsafe.get_ref();
        for (v, what) in [
            (f.channel_timeout, "channel_timeout"),
            (f.router_timeout, "router_timeout"),
        ] {
            if !(v.is_finite() && v > 0.0 && v <= 3600.0) {
                return Err((
                    at(self.failsafe.span()),
                    format!("[failsafe] `{what}` = {v}: expected seconds in (0, 3600]"),
                ));
            }
        }
        Ok(())
    }

    fn validate_links(&self) -> Result<(), Problem> {
        if !self.links.is_empty() && !self.link.span().is_empty() {
            return Err((
                at(self.link.span()),
                "give either [link] or [[links]], not both".to_string(),
            ));
        }
        if self.links.len() > 8 {
            return Err((at(self.links[8].span()), "at most 8 links".to_string()));
        }
        for link in &self.links {
            if let LinkConfig::Serial {
                telemetry_rate_hz: Some(hz),
                ..
            } = &link.get_ref().0
                && !(hz.is_finite() && *hz > 0.0 && *hz <= 1000.0)
            {
                return Err((
                    at(link.span()),
                    format!("telemetry_rate_hz = {hz}: expected a rate in (0, 1000] Hz"),
                ));
            }
        }
        let f = self.failover;
        let timeout_ok =
            f.link_timeout.is_finite() && f.link_timeout > 0.0 && f.link_timeout <= 60.0;
        let probe_ok =
            f.probe_period.is_finite() && f.probe_period > 0.0 && f.probe_period < f.link_timeout;
        if !(timeout_ok && probe_ok) {
            return Err((
                None,
                format!(
                    "[failover] link_timeout = {} and probe_period = {}: expected 0 < probe_period < link_timeout <= 60 s",
                    f.link_timeout, f.probe_period
                ),
            ));
        }
        Ok(())
    }

    fn validate_filter(&self) -> Result<(), Problem> {
        let window = self.filter.get_ref().window;
        if !(1..=255).contains(&window) {
            return Err((
                at(self.filter.span()),
                format!("[filter] `window` = {window}: expected 1 to 255 samples"),
            ));
        }
        Ok(())
    }

    /// An L298 driver needs one channel per motor of the platform, and duty
    /// and PWM settings it can use.
    fn validate_actuators(&self) -> Result<(), Problem> {
        let ActuatorConfig::L298 {
            channels,
            pwm_frequency,
            min_duty,
            max_duty,
            deadband,
        } = self.actuators()
        else {
            return Ok(());
        };
        let problem = |message: String| (at(self.actuators.span()), message);
        let motors = self.platform().build().motors();
        if channels.len() != motors {
            return Err(problem(format!(
                "[actuators] {} L298 channels for a platform with {motors} motors",
                channels.len()
            )));
        }
        let ok = |v: f64| v.is_finite() && (0.0..=1.0).contains(&v);
        if !(ok(*min_duty) && ok(*max_duty) && ok(*deadband) && min_duty <= max_duty) {
            return Err(problem(
                "[actuators] expected 0 <= min_duty <= max_duty <= 1 and 0 <= deadband <= 1"
                    .to_string(),
            ));
        }
        if !(pwm_frequency.is_finite() && *pwm_frequency > 0.0) {
            return Err(problem(
                "[actuators] pwm_frequency: expected a positive frequency in Hz".to_string(),
            ));
        }
        Ok(())
    }

    /// Encoders need a wheeled platform, one encoder per wheel with the
    /// channels its kind uses, GPIO pins of their own, and numbers in range.
    fn validate_encoders(&self) -> Result<(), Problem> {
        let Some(spanned) = &self.encoders else {
            return Ok(());
        };
        let e = spanned.get_ref();
        let problem = |message: String| (at(spanned.span()), format!("[encoders] {message}"));
        let platform = self.platform().build();
        if platform.max_wheel_speed().is_none() {
            return Err(problem(format!(
                "need a wheeled platform (diff-drive, kiwi); a {}'s outputs are not wheels",
                platform.name()
            )));
        }
        let wheels = platform.motors();
        if e.channels.len() != wheels {
            return Err(problem(format!(
                "`channels`: {} encoders for a platform with {wheels} wheels",
                e.channels.len()
            )));
        }
        let quadrature = e.kind == Counting::Quadrature;
        if let Some(i) = e.channels.iter().position(|c| c.b.is_some() != quadrature) {
            let expected = if quadrature {
                "quadrature encoders need pins `a` and `b`"
            } else {
                "single-channel encoders have pin `a` only"
            };
            return Err(problem(format!("`channels`: wheel {}: {expected}", i + 1)));
        }
        let mut pins: Vec<u8> = e
            .channels
            .iter()
            .flat_map(|c| [Some(c.a), c.b])
            .flatten()
            .collect();
        if let ActuatorConfig::L298 { channels, .. } = self.actuators() {
            pins.extend(channels.iter().flat_map(|c| [c.in1, c.in2, c.enable]));
        }
        let mut seen = std::collections::BTreeSet::new();
        if let Some(pin) = pins.iter().find(|p| !seen.insert(**p)) {
            return Err(problem(format!(
                "`channels`: GPIO {pin} is used twice (encoders and actuators need a pin each)"
            )));
        }
        let positive = |v: f64| v.is_finite() && v > 0.0;
        for (v, what) in [
            (e.counts_per_revolution, "counts_per_revolution"),
            (e.wheel_radius, "wheel_radius"),
            (e.position_sigma, "position_sigma"),
            (e.heading_sigma, "heading_sigma"),
            (e.odometry_sigma, "odometry_sigma"),
        ] {
            if !positive(v) {
                return Err(problem(format!(
                    "`{what}` = {v}: expected a positive number"
                )));
            }
        }
        for (v, what) in [(e.kp, "kp"), (e.ki, "ki")] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(problem(format!("`{what}` = {v}: expected a gain >= 0")));
            }
        }
        if !(positive(e.stall_output) && e.stall_output <= 1.0) {
            return Err(problem(format!(
                "`stall_output` = {}: expected a fraction of full output in (0, 1]",
                e.stall_output
            )));
        }
        if !(positive(e.stall_time) && e.stall_time <= 60.0) {
            return Err(problem(format!(
                "`stall_time` = {}: expected seconds in (0, 60]",
                e.stall_time
            )));
        }
        Ok(())
    }

    pub fn platform(&self) -> &PlatformSpec {
        &self.platform.get_ref().0
    }

    pub fn link(&self) -> &LinkConfig {
        &self.link.get_ref().0
    }

    /// Every link to the router, in order of preference: `[[links]]`, or
    /// the one `[link]`.
    pub fn links(&self) -> Vec<&LinkConfig> {
        if self.links.is_empty() {
            vec![self.link()]
        } else {
            self.links.iter().map(|l| &l.get_ref().0).collect()
        }
    }

    pub fn actuators(&self) -> &ActuatorConfig {
        &self.actuators.get_ref().0
    }

    pub fn position(&self) -> &PositionConfig {
        &self.position.get_ref().0
    }

    pub fn control_period(&self) -> Duration {
        Duration::from_secs_f64(1.0 / *self.control_rate_hz.get_ref())
    }

    /// Settings of the agent core.
    pub fn agent_settings(&self, simulated: bool) -> AgentSettings {
        let f = self.failsafe.get_ref();
        let mut s = AgentSettings::new(self.name.get_ref().clone());
        s.failsafe = FailsafeConfig {
            channel_timeout: Duration::from_secs_f64(f.channel_timeout),
            router_timeout: Duration::from_secs_f64(f.router_timeout),
            mission_continues_on_link_loss: f.mission_continues_on_link_loss,
        };
        s.telemetry_period = Duration::from_secs_f64(1.0 / *self.telemetry_rate_hz.get_ref());
        s.notify_not_routed = self.notify_not_routed;
        s.filter_window = self.filter.get_ref().window;
        let position = self.position();
        s.external_position = !simulated && matches!(position, PositionConfig::External);
        s.has_position = simulated || !matches!(position, PositionConfig::None);
        s.gains = self.control;
        s.safety = *self.safety.get_ref();
        if let Some(e) = &self.encoders {
            s.wheels = Some(e.get_ref().wheel_settings());
            s.fusion = e.get_ref().fusion_settings();
        }
        s
    }

    /// The `[encoders]` section, if the robot has encoders.
    pub fn encoders(&self) -> Option<&EncoderConfig> {
        self.encoders.as_ref().map(Spanned::get_ref)
    }
}

/// The sections of a vehicle that something else drives: an autopilot
/// (`[autopilot]`) or a ROS 2 base (`[ros2]`).
impl RobotConfig {
    /// An autopilot or a ROS 2 base drives the vehicle: it gives the
    /// position and takes the place of actuators (a base, of encoders too).
    fn validate_vehicle(&self) -> Result<(), Problem> {
        let (name, drives, span, checked) = match (&self.autopilot, &self.ros2) {
            (Some(_), Some(ros2)) => {
                let text = "[ros2] and [autopilot] both drive the vehicle: keep one";
                return Err((at(ros2.span()), text.to_string()));
            }
            (Some(a), None) => (
                "[autopilot]",
                "flies the vehicle",
                a.span(),
                a.get_ref().validate(),
            ),
            (None, Some(r)) => (
                "[ros2]",
                "drives the base through its cmd_vel",
                r.span(),
                r.get_ref().validate(),
            ),
            (None, None) => return Ok(()),
        };
        let problem = |message: String| (at(span.clone()), message);
        checked.map_err(problem)?;
        if !matches!(self.position(), PositionConfig::None | PositionConfig::Sim) {
            return Err(problem(format!(
                "{name} gives the position: leave out [position]"
            )));
        }
        if !matches!(self.actuators(), ActuatorConfig::None) {
            return Err(problem(format!("{name} {drives}: leave out [actuators]")));
        }
        if self.ros2.is_some() && self.encoders.is_some() {
            return Err(problem(
                "[ros2] measures the velocity (the base's odometry): leave out [encoders]".into(),
            ));
        }
        Ok(())
    }

    /// The `[ros2]` section, if any.
    pub fn ros2(&self) -> Option<&crate::ros2_base::Ros2Config> {
        self.ros2.as_ref().map(|r| r.get_ref())
    }

    /// The `[autopilot]` section, if any.
    pub fn autopilot(&self) -> Option<&crate::autopilot::AutopilotConfig> {
        self.autopilot.as_ref().map(|a| a.get_ref())
    }

    /// Replaces the `[autopilot]` section's MAVLink link (`mech-agent
    /// --autopilot LINK`: a second simulator on another port, a flight
    /// controller on another UART), checked as the file's would be. `Err`
    /// says why not: a bad link, or no `[autopilot]` section to change.
    pub fn set_autopilot_link(&mut self, link: &str) -> Result<(), String> {
        let Some(section) = self.autopilot.as_mut() else {
            return Err("this robot's config has no [autopilot] section".to_string());
        };
        let mut changed = section.get_ref().clone();
        changed.link = link.to_string();
        changed.validate()?;
        *section.get_mut() = changed;
        Ok(())
    }
}

/// A table whose `kind` key picks the variant of `T` and whose other keys
/// are that variant's fields (`[platform] kind = "kiwi"  radius = 0.1`).
///
/// Deserialized in two steps (kind, then the variant from the rest) rather
/// than as a serde internally tagged enum, whose buffering would drop the
/// name of a mistyped key from error messages.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Kind<T>(pub T);

impl<'de, T: serde::de::DeserializeOwned> Deserialize<'de> for Kind<T> {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        let mut table = toml::Table::deserialize(d)?;
        let kind = match table.remove("kind") {
            Some(toml::Value::String(k)) => k,
            Some(other) => {
                return Err(D::Error::custom(format!(
                    "`kind` must be a string, not {}",
                    other.type_str()
                )));
            }
            None => return Err(D::Error::custom("missing `kind`")),
        };
        let as_table = |table: toml::Table| {
            let mut outer = toml::Table::new();
            outer.insert(kind.clone(), toml::Value::Table(table));
            toml::Value::Table(outer).try_into::<T>()
        };
        let result = if table.is_empty() {
            // A variant without fields (`kind = "none"`), or one whose
            // fields all have defaults.
            toml::Value::String(kind.clone())
                .try_into::<T>()
                .or_else(|_| as_table(table))
        } else {
            as_table(table)
        };
        // Display (not message()) keeps the "in `key`" context.
        result
            .map(Kind)
            .map_err(|e| D::Error::custom(e.to_string().trim().replace('\n', " ")))
    }
}

/// A problem [`RobotConfig::validate`] found: where in the file (the value,
/// or its table; `None` for a defaulted one) and what is wrong.
type Problem = (Option<Range<usize>>, String);

/// The span of a value in the file; a defaulted value has an empty one.
fn at(span: Range<usize>) -> Option<Range<usize>> {
    (!span.is_empty()).then_some(span)
}

/// Checks a robot name (from the file or `--name`).
pub fn check_name(name: &str) -> Result<(), String> {
    if name.is_empty()
        || name.len() > mech_proto::MAX_NAME_LEN
        || name.chars().any(|c| c.is_whitespace() || c.is_control())
    {
        Err(format!(
            "name {name:?}: expected 1 to {} characters without spaces",
            mech_proto::MAX_NAME_LEN
        ))
    } else {
        Ok(())
    }
}

/// When an error is reported against a whole `[section]` but names one of
/// its keys in backticks, the offset of that key's line instead.
fn refine(text: &str, section_start: usize, message: &str) -> usize {
    let Some(section) = text.get(section_start..).filter(|s| s.starts_with('[')) else {
        return section_start;
    };
    let mut keys: Vec<&str> = message.split('`').skip(1).step_by(2).collect();
    if message.contains("unknown variant") {
        keys.insert(0, "kind");
    }
    for key in keys {
        let mut offset = section_start;
        for (i, line) in section.split_inclusive('\n').enumerate() {
            let trimmed = line.trim_start();
            if i > 0 && trimmed.starts_with('[') {
                break;
            }
            let is_key = trimmed
                .strip_prefix(key)
                .is_some_and(|rest| rest.trim_start().starts_with('='));
            if i > 0 && !key.is_empty() && is_key {
                return offset + (line.len() - trimmed.len());
            }
            offset += line.len();
        }
    }
    section_start
}

/// 1-based line and column of a byte offset.
fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, column)
}

#[cfg(test)]
mod tests {
    use super::*;

    const MINIMAL: &str =
        "name = \"r1\"\n[platform]\nkind = \"kiwi\"\nradius = 0.1\nmax_wheel_speed = 0.5\n";

    #[test]
    fn minimal_config_gets_defaults() {
        let c = RobotConfig::parse(MINIMAL, "r1.toml").unwrap();
        assert_eq!(c.name.get_ref(), "r1");
        assert_eq!(
            *c.link(),
            LinkConfig::Udp {
                router: "127.0.0.1:7400".parse().unwrap()
            }
        );
        let s = c.agent_settings(false);
        assert_eq!(s.failsafe, FailsafeConfig::default());
        assert_eq!(s.telemetry_period, Duration::from_millis(50));
        assert_eq!(s.filter_window, 9);
        assert_eq!(c.control_period(), Duration::from_millis(20));
    }

    fn error(text: &str) -> String {
        RobotConfig::parse(text, "bad.toml")
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn the_safety_table_has_defaults_and_its_mistakes_are_located() {
        let c = RobotConfig::parse(MINIMAL, "r1.toml").unwrap();
        assert_eq!(*c.safety.get_ref(), crate::safety::SafetyConfig::default());
        let c = RobotConfig::parse(
            &format!("{MINIMAL}[safety]\nradius = 0.2\nmax_deceleration = 2.0\n"),
            "r1.toml",
        )
        .unwrap();
        assert_eq!(c.safety.get_ref().radius, 0.2);
        assert_eq!(c.safety.get_ref().max_deceleration, 2.0);
        // The agent core (and a `--sim` robot) runs with it.
        for simulated in [false, true] {
            assert_eq!(c.agent_settings(simulated).safety, *c.safety.get_ref());
        }
        let e = error(&format!("{MINIMAL}[safety]\nradius = -0.2\n"));
        assert!(
            e.contains("bad.toml:6") && e.contains("safety.radius"),
            "{e}"
        );
        let e = error(&format!("{MINIMAL}[safety]\nradios = 0.2\n"));
        assert!(e.contains("bad.toml:7") && e.contains("radios"), "{e}");
    }

    #[test]
    fn errors_name_file_line_and_expectation() {
        let e = error(&format!("{MINIMAL}telemetry_rate_hz = \"fast\"\n"));
        assert!(e.starts_with("bad.toml:"), "{e}");
        let e = error(
            "name = \"r1\"\n[platform]\nkind = \"diff-drive\"\ntrack_width = \"wide\"\nmax_wheel_speed = 0.5\n",
        );
        assert!(
            e.starts_with("bad.toml:4:1:")
                && e.contains("expected f64")
                && e.contains("track_width"),
            "{e}"
        );
        let e = error(
            "name = \"r1\"\n[platform]\nkind = \"diff-drive\"\nmax_wheel_speed = 0.5\ntrak_width = 0.1\n",
        );
        assert!(
            e.starts_with("bad.toml:5:1:") && e.contains("unknown field `trak_width`"),
            "{e}"
        );
        let e = error("name = \"r1\"\n\n[platform]\nkind = \"hexapod\"\n");
        assert!(
            e.starts_with("bad.toml:4:1:") && e.contains("hexapod") && e.contains("diff-drive"),
            "{e}"
        );
        let e = error(&format!("{MINIMAL}[failsafe]\nchannel_timout = 0.5\n"));
        assert!(
            e.starts_with("bad.toml:7:1:") && e.contains("channel_timout"),
            "{e}"
        );
        let e = error(&format!("{MINIMAL}[filter]\nwindow = 0\n"));
        assert!(
            e.starts_with("bad.toml:7:1:") && e.contains("`window` = 0"),
            "{e}"
        );
        let e = error(
            "name = \"r 1\"\n[platform]\nkind = \"kiwi\"\nradius = 0.1\nmax_wheel_speed = 0.5\n",
        );
        assert!(
            e.starts_with("bad.toml:1:8:") && e.contains("without spaces"),
            "{e}"
        );
        let e = error(
            "name = \"r1\"\n[platform]\nkind = \"kiwi\"\nradius = -0.1\nmax_wheel_speed = 0.5\n",
        );
        assert!(
            e.starts_with("bad.toml:4:1:") && e.contains("`radius` must be a positive number"),
            "{e}"
        );
        let e = error(&format!(
            "{MINIMAL}[actuators]\nkind = \"l298\"\nchannels = [{{ in1 = 5, in2 = 6, enable = 12 }}]\n"
        ));
        assert!(
            e.contains("1 L298 channels for a platform with 3 motors"),
            "{e}"
        );
        let e = error("name = \"r1\"\n");
        assert!(e.contains("platform"), "{e}");
    }

    const L298_DIFF_DRIVE: &str = "name = \"r1\"\n[platform]\nkind = \"diff-drive\"\ntrack_width = 0.15\nmax_wheel_speed = 0.45\n[actuators]\nkind = \"l298\"\nchannels = [{ in1 = 6, in2 = 12, enable = 20 }, { in1 = 13, in2 = 19, enable = 26 }]\n";

    #[test]
    fn encoders_become_wheel_and_fusion_settings() {
        let text = format!(
            "{L298_DIFF_DRIVE}[encoders]\nkind = \"single-channel\"\nchannels = [{{ a = 17 }}, {{ a = 27 }}]\ncounts_per_revolution = 40\nwheel_radius = 0.033\nclosed_loop = false\nstall_time = 0.8\nposition_sigma = 0.08\n"
        );
        let c = RobotConfig::parse(&text, "r1.toml").unwrap();
        let s = c.agent_settings(false);
        let w = s.wheels.unwrap();
        assert_eq!(w.counting, Counting::SingleChannel);
        assert_eq!(w.speed_loop, None);
        assert_eq!(w.stall.time, Duration::from_millis(800));
        assert_eq!(w.stall.output, StallSettings::default().output);
        assert_eq!(s.fusion.position_sigma, 0.08);
        assert!(
            RobotConfig::parse(L298_DIFF_DRIVE, "r1.toml")
                .unwrap()
                .agent_settings(false)
                .wheels
                .is_none()
        );
    }

    #[test]
    fn encoder_mistakes_are_named() {
        let encoders = |body: &str| error(&format!("{L298_DIFF_DRIVE}\n[encoders]\n{body}"));
        let quad = "kind = \"quadrature\"\ncounts_per_revolution = 1440\nwheel_radius = 0.033\n";
        let e = encoders(&format!("{quad}channels = [{{ a = 17, b = 18 }}]\n"));
        assert!(e.contains("1 encoders for a platform with 2 wheels"), "{e}");
        let e = encoders(&format!(
            "{quad}channels = [{{ a = 17, b = 18 }}, {{ a = 22 }}]\n"
        ));
        assert!(
            e.contains("wheel 2: quadrature encoders need pins `a` and `b`"),
            "{e}"
        );
        let e = encoders(&format!(
            "{quad}channels = [{{ a = 17, b = 18 }}, {{ a = 22, b = 26 }}]\n"
        ));
        assert!(e.contains("GPIO 26 is used twice"), "{e}");
        let e = encoders(
            "kind = \"single-channel\"\ncounts_per_revolution = 40\nwheel_radius = -1\nchannels = [{ a = 17 }, { a = 22 }]\n",
        );
        // The line of the key at fault.
        assert!(
            e.starts_with("bad.toml:13:1:") && e.contains("`wheel_radius` = -1"),
            "{e}"
        );
        let e = encoders(&format!(
            "{quad}channels = [{{ a = 17, b = 18 }}, {{ a = 22, b = 23 }}]\nstall_output = 1.5\n"
        ));
        assert!(e.contains("`stall_output` = 1.5"), "{e}");
        let e = encoders("kind = \"optical\"\n");
        assert!(e.contains("optical") && e.contains("single-channel"), "{e}");
        let e = error(&format!(
            "name = \"q\"\n[platform]\nkind = \"quadcopter\"\nmax_speed = 1\nmax_climb = 1\nmax_yaw_rate = 1\n[encoders]\n{quad}channels = []\n"
        ));
        assert!(e.contains("need a wheeled platform"), "{e}");
    }

    #[test]
    fn several_links_in_order_of_preference_or_one_link_but_not_both() {
        let two = format!(
            "{MINIMAL}[[links]]\nkind = \"udp\"\nrouter = \"10.0.0.1:7400\"\n\
             [[links]]\nkind = \"serial\"\nport = \"/dev/ttyUSB0\"\ntelemetry_rate_hz = 5\n"
        );
        let c = RobotConfig::parse(&two, "r1.toml").unwrap();
        let links = c.links();
        assert_eq!(links.len(), 2);
        assert!(matches!(links[0], LinkConfig::Udp { .. }));
        assert!(matches!(
            links[1],
            LinkConfig::Serial {
                telemetry_rate_hz: Some(5.0),
                baud: 57_600,
                ..
            }
        ));
        assert_eq!(c.failover, FailoverConfig::default());
        assert_eq!(
            RobotConfig::parse(MINIMAL, "r1.toml")
                .unwrap()
                .links()
                .len(),
            1
        );
        let both = format!("{two}[link]\nkind = \"udp\"\n");
        assert!(
            error(&both).contains("either [link] or [[links]]"),
            "{}",
            error(&both)
        );
        let bad = format!("{MINIMAL}[failover]\nlink_timeout = 0.2\nprobe_period = 0.5\n");
        assert!(error(&bad).contains("probe_period"), "{}", error(&bad));
    }

    #[test]
    fn a_ros2_base_gives_the_position_and_drives_alone() {
        let ros2 = format!("{MINIMAL}[ros2]\nnamespace = \"/tb3_1\"\n");
        let c = RobotConfig::parse(&ros2, "tb3.toml").unwrap();
        assert_eq!(c.ros2().unwrap().resolve("odom"), "/tb3_1/odom");
        let e = error(&format!("{ros2}odom_timeout = -1.0\n"));
        assert!(e.contains("odom_timeout"), "{e}");
        for (extra, says) in [
            ("[position]\nkind = \"external\"\n", "leave out [position]"),
            ("[autopilot]\nlink = \"udpin:0.0.0.0:14540\"\n", "keep one"),
            (
                "[encoders]\nkind = \"single-channel\"\ncounts_per_revolution = 40\nwheel_radius = 0.033\nchannels = [{ a = 17 }, { a = 22 }, { a = 23 }]\n",
                "leave out [encoders]",
            ),
        ] {
            let e = error(&format!("{ros2}{extra}"));
            assert!(e.contains(says), "{extra}: {e}");
        }
    }

    #[test]
    fn example_configs_parse() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/agents");
        let mut seen = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "toml") {
                let c = RobotConfig::load(&path).unwrap_or_else(|e| panic!("{e}"));
                assert!(!c.name.get_ref().is_empty());
                seen += 1;
            }
        }
        assert!(seen >= 4, "{seen} example configs");
    }
}
