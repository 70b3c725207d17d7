//! Property tests: every body round-trips through the plain codec, the TCP
//! stream framing (split at arbitrary read boundaries) and the serial framing.

use mech_proto::framing::{SerialDecoder, StreamDecoder, write_serial_frame, write_stream_frame};
use mech_proto::*;
use proptest::collection::vec;
use proptest::prelude::*;
use proptest::strategy::ValueTree;

fn name() -> impl Strategy<Value = String> {
    "[a-z][a-z0-9_/]{0,20}"
}

fn maybe_name() -> impl Strategy<Value = String> {
    prop_oneof![Just(String::new()), name()]
}

fn text() -> impl Strategy<Value = String> {
    ".{0,40}"
}

fn real() -> impl Strategy<Value = f64> {
    -1.0e6..1.0e6f64
}

fn unit() -> impl Strategy<Value = f64> {
    -1.0..=1.0f64
}

fn fraction() -> impl Strategy<Value = f64> {
    0.0..=1.0f64
}

fn pose() -> impl Strategy<Value = Pose> {
    (real(), real(), real(), -3.2..3.2f64).prop_map(|(x, y, z, heading)| Pose { x, y, z, heading })
}

fn command() -> impl Strategy<Value = Command> {
    prop_oneof![
        vec(unit(), 0..=MAX_MOTORS).prop_map(|outputs| Command::Actuators(Actuators { outputs })),
        (unit(), unit()).prop_map(|(steering, throttle)| Command::SteeringThrottle(
            SteeringThrottle { steering, throttle }
        )),
        (real(), real()).prop_map(
            |(speed, heading)| Command::VelocityHeading(VelocityHeading { speed, heading })
        ),
        (real(), real(), real(), real()).prop_map(|(vx, vy, vz, wz)| Command::Twist(Twist {
            vx,
            vy,
            vz,
            wz
        })),
        Just(Command::Stop(Stop {})),
    ]
}

fn capability() -> impl Strategy<Value = CommandKind> {
    proptest::sample::select(CommandKind::ALL.to_vec())
}

fn route() -> impl Strategy<Value = Route> {
    (name(), maybe_name(), any::<u32>()).prop_map(|(robot, channel, epoch)| Route {
        robot,
        channel,
        epoch,
    })
}

fn point() -> impl Strategy<Value = Point> {
    (-1.0e4..1.0e4f64, -1.0e4..1.0e4f64).prop_map(|(x, y)| Point { x, y })
}

/// A simple polygon: `n` vertices at increasing angles around a centre, each
/// at its own radius (star-shaped about the centre, so its edges never
/// cross).
fn polygon(max: usize) -> impl Strategy<Value = Vec<Point>> {
    (point(), vec(0.1..50.0f64, 3..=max)).prop_map(|(c, radii)| {
        let n = radii.len() as f64;
        radii
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let a = i as f64 / n * std::f64::consts::TAU;
                Point {
                    x: c.x + r * a.cos(),
                    y: c.y + r * a.sin(),
                }
            })
            .collect()
    })
}

fn arena() -> impl Strategy<Value = Arena> {
    (
        (name(), any::<u32>(), any::<bool>()),
        proptest::option::of(polygon(MAX_BOUNDARY_VERTICES)),
        vec(polygon(12), 0..4),
        vec((polygon(12), 0.0..2.0f64), 0..3),
        0.0..1.0f64,
    )
        .prop_map(|((robot, id, enabled), boundary, keep_out, slow, margin)| {
            // Keep-outs and slow zones need a boundary.
            let (keep_out, slow) = match boundary {
                Some(_) => (keep_out, slow),
                None => (vec![], vec![]),
            };
            Arena {
                robot,
                id,
                enabled,
                boundary: boundary.unwrap_or_default(),
                keep_out,
                slow_zones: slow
                    .into_iter()
                    .map(|(polygon, max_speed)| SlowZone { polygon, max_speed })
                    .collect(),
                margin,
            }
        })
}

fn neighbours() -> impl Strategy<Value = Neighbours> {
    let neighbour = (
        any::<u16>(),
        (point(), -100.0..100.0f64),
        (-10.0..10.0f64, -10.0..10.0f64, -5.0..5.0f64),
        (0.0..5.0f64, any::<u32>(), any::<bool>()),
    )
        .prop_map(
            |(id, (p, z), (vx, vy, vz), (radius, age_ms, cooperative))| Neighbour {
                id,
                x: p.x,
                y: p.y,
                z,
                vx,
                vy,
                vz,
                radius,
                age_ms,
                cooperative,
            },
        );
    let obstacle = prop_oneof![
        (point(), 0.0..10.0f64).prop_map(|(c, radius)| Obstacle::Disc(Disc {
            x: c.x,
            y: c.y,
            radius
        })),
        polygon(MAX_POLYGON_VERTICES).prop_map(Obstacle::Polygon),
    ];
    (
        name(),
        any::<u64>(),
        vec(neighbour, 0..20),
        vec(obstacle, 0..4),
    )
        .prop_map(|(robot, stamp_us, robots, obstacles)| Neighbours {
            robot,
            stamp_us,
            robots,
            obstacles,
        })
}

fn safety_report() -> impl Strategy<Value = SafetyReport> {
    (
        0..3usize,
        any::<u32>(),
        0..Intervention::ALL.len(),
        vec(any::<u32>(), 6),
        (0.0..5.0f64, 0.0..1.0f64),
    )
        .prop_map(
            |(state, arena, intervention, c, (radius, position_error))| SafetyReport {
                state: [SafetyState::NoArena, SafetyState::On, SafetyState::Off][state],
                arena,
                intervention: Intervention::ALL[intervention],
                counts: InterventionCounts {
                    fence: c[0],
                    keep_out: c[1],
                    separation: c[2],
                    stale_neighbours: c[3],
                    slow_zone: c[4],
                    returning: c[5],
                },
                radius,
                position_error,
            },
        )
}

fn body() -> impl Strategy<Value = Body> {
    let hello = (
        name(),
        name(),
        vec(capability(), 0..6),
        0..=32u8,
        real(),
        real(),
        text(),
    )
        .prop_map(
            |(name, platform, capabilities, motors, max_speed, max_yaw_rate, agent_version)| {
                Body::Hello(Hello {
                    name,
                    platform,
                    capabilities,
                    motors,
                    max_speed,
                    max_yaw_rate,
                    agent_version,
                })
            },
        );
    let welcome = (any::<u16>(), route(), text()).prop_map(|(robot_id, route, router_version)| {
        Body::Welcome(Welcome {
            robot_id,
            route,
            router_version,
        })
    });
    let telemetry = (
        pose(),
        (real(), real(), real(), real()),
        0..=6u8,
        maybe_name(),
        (any::<bool>(), 0..=4u8, 0..=2u8),
        proptest::option::of(fraction()),
        fraction(),
        vec(unit(), 0..8),
        proptest::option::of((any::<u32>(), any::<u32>(), any::<u32>())),
        (
            any::<u32>(),
            any::<bool>(),
            proptest::option::of(safety_report()),
        ),
    )
        .prop_map(
            |(
                pose,
                (vx, vy, vz, wz),
                mode,
                channel,
                (off, fs, health),
                battery,
                q,
                actuators,
                mission,
                (stale, measured, safety),
            )| {
                Body::Telemetry(Telemetry {
                    pose,
                    velocity: Velocity { vx, vy, vz, wz },
                    mode: [
                        ControlMode::Idle,
                        ControlMode::Actuators,
                        ControlMode::SteeringThrottle,
                        ControlMode::VelocityHeading,
                        ControlMode::Twist,
                        ControlMode::Waypoints,
                        ControlMode::Stopped,
                    ][mode as usize],
                    channel,
                    computation: if off {
                        Computation::Offboard
                    } else {
                        Computation::Onboard
                    },
                    failsafe: [
                        FailsafeState::Ok,
                        FailsafeState::ChannelSilent,
                        FailsafeState::RouterLost,
                        FailsafeState::EStopped,
                        FailsafeState::Fault,
                    ][fs as usize],
                    health: [Health::Ok, Health::Degraded, Health::Fault][health as usize],
                    battery,
                    position_quality: q,
                    actuators,
                    mission: mission.map(|(id, next, total)| MissionProgress { id, next, total }),
                    stale,
                    velocity_source: if measured {
                        VelocitySource::Measured
                    } else {
                        VelocitySource::Commanded
                    },
                    safety,
                })
            },
        );
    let waypoint = (
        real(),
        real(),
        real(),
        proptest::option::of(0.0..=mech_proto::MAX_WAYPOINT_TIME),
    )
        .prop_map(|(x, y, z, time)| Waypoint { x, y, z, time });
    let mission = (
        any::<u32>(),
        vec(waypoint, 0..20),
        any::<bool>(),
        0.001..10.0f64,
        any::<u32>(),
    )
        .prop_map(|(id, waypoints, looped, arrival_radius, start)| {
            let start_index = start % (waypoints.len() as u32 + 1);
            Body::Mission(Mission {
                id,
                waypoints,
                looped,
                arrival_radius,
                start_index,
            })
        });
    let fleet = vec((name(), command()), 0..10).prop_map(|parts| {
        Body::FleetCommand(FleetCommand {
            parts: parts
                .into_iter()
                .map(|(robot, command)| RobotCommand { robot, command })
                .collect(),
        })
    });
    let channels = vec(
        (
            name(),
            maybe_name(),
            0.0..1000.0f64,
            vec(name(), 0..4),
            any::<u64>(),
        ),
        0..5,
    )
    .prop_map(|list| {
        Body::Channels(Channels {
            channels: list
                .into_iter()
                .map(|(name, publisher, rate_hz, robots, idle_ms)| ChannelInfo {
                    name,
                    publisher,
                    rate_hz,
                    robots,
                    idle_ms,
                })
                .collect(),
        })
    });
    let goal = prop_oneof![
        (real(), real(), real(), real()).prop_map(
            |(vx, vy, wz, scale_rate)| ClusterGoal::Velocity(ClusterVelocity {
                vx,
                vy,
                wz,
                scale_rate
            })
        ),
        (real(), real(), real(), real()).prop_map(|(x, y, heading, scale)| ClusterGoal::Pose(
            ClusterPose {
                x,
                y,
                heading,
                scale
            }
        )),
    ];
    let formation =
        (0..=4u8, real(), vec((real(), real()), 0..6)).prop_map(|(k, spacing, offsets)| {
            Formation {
                kind: [
                    FormationKind::Line,
                    FormationKind::Column,
                    FormationKind::Wedge,
                    FormationKind::Circle,
                    FormationKind::Custom,
                ][k as usize],
                spacing,
                offsets: offsets.into_iter().map(|(x, y)| Offset { x, y }).collect(),
            }
        });
    let cluster = (
        name(),
        vec(name(), 0..6),
        goal,
        proptest::option::of(formation),
    )
        .prop_map(|(cluster, members, goal, formation)| {
            Body::Cluster(ClusterCommand {
                cluster,
                members,
                goal,
                formation,
            })
        });
    let notice = (0..=3u8, 0..=8u16, text()).prop_map(|(level, code, text)| {
        Body::Notice(Notice {
            level: [Level::Debug, Level::Info, Level::Warn, Level::Error][level as usize],
            code: [
                NoticeCode::Text,
                NoticeCode::BadMessage,
                NoticeCode::UnknownRobot,
                NoticeCode::NotRouted,
                NoticeCode::Unsupported,
                NoticeCode::Failsafe,
                NoticeCode::DriverFault,
                NoticeCode::Safety,
                NoticeCode::NotPermitted,
            ][code as usize],
            text,
        })
    });
    prop_oneof![
        hello,
        welcome,
        (
            any::<u64>(),
            proptest::option::of((any::<u32>(), any::<u64>()))
        )
            .prop_map(|(uptime_ms, echo)| Body::Heartbeat(Heartbeat {
                uptime_ms,
                echo: echo.map(|(seq, held_us)| Echo { seq, held_us }),
            })),
        telemetry,
        command().prop_map(Body::Command),
        fleet,
        mission,
        (any::<u32>(), any::<bool>(), text()).prop_map(|(id, accepted, reason)| Body::MissionAck(
            MissionAck {
                id,
                accepted,
                reason
            }
        )),
        route().prop_map(Body::Route),
        route().prop_map(|r| Body::RouteAck(RouteAck {
            robot: r.robot,
            channel: r.channel,
            epoch: r.epoch
        })),
        (any::<bool>(), any::<u32>()).prop_map(|(engage, id)| Body::EStop(EStop { engage, id })),
        (any::<bool>(), any::<u32>())
            .prop_map(|(engage, id)| Body::EStopAck(EStopAck { engage, id })),
        Just(Body::ChannelsRequest(ChannelsRequest {})),
        channels,
        cluster,
        notice,
        any::<bool>().prop_map(|telemetry| Body::Subscribe(Subscribe { telemetry })),
        (name(), pose(), fraction()).prop_map(|(robot, pose, quality)| Body::PositionFix(
            PositionFix {
                robot,
                pose,
                quality
            }
        )),
        text().prop_map(|reason| Body::Bye(Bye { reason })),
        any::<u64>().prop_map(|nonce| Body::TimeRequest(TimeRequest { nonce })),
        (any::<u64>(), any::<u64>())
            .prop_map(|(nonce, station_us)| Body::Time(Time { nonce, station_us })),
        (name(), 0..6usize, 0.1f64..500.0).prop_map(|(robot, action, altitude)| {
            let action = AutopilotAction::ALL[action];
            let altitude = if action == AutopilotAction::Takeoff {
                altitude
            } else {
                0.0
            };
            Body::Autopilot(AutopilotRequest {
                robot,
                action,
                altitude,
            })
        }),
        arena().prop_map(Body::Arena),
        (name(), any::<u32>()).prop_map(|(robot, id)| Body::ArenaAck(ArenaAck { robot, id })),
        neighbours().prop_map(Body::Neighbours),
    ]
}

fn envelope() -> impl Strategy<Value = Envelope> {
    (
        any::<u32>(),
        any::<u64>(),
        name(),
        maybe_name(),
        maybe_name(),
        body(),
        proptest::option::of(vec(any::<u8>(), 0..=MAX_AUTH_LEN)),
    )
        .prop_map(
            |(seq, stamp_us, sender, destination, channel, body, auth)| Envelope {
                header: Header {
                    seq,
                    stamp_us,
                    sender,
                    destination,
                    channel,
                },
                body,
                auth: auth.map(AuthTag::from),
            },
        )
}

/// Frames `envs` with `write`, feeds the byte stream to a decoder in chunks
/// of the sizes in `cuts` (as reads from a socket or port would split it)
/// through `feed`, and returns every message decoded, in order.
fn through_chunks(
    envs: &[Envelope],
    cuts: &[usize],
    write: fn(&Envelope, &mut Vec<u8>) -> Result<(), Error>,
    mut feed: impl FnMut(&[u8]) -> Vec<Result<Envelope, Error>>,
) -> Vec<Envelope> {
    let mut stream = Vec::new();
    for env in envs {
        write(env, &mut stream).unwrap();
    }
    let mut got = Vec::new();
    let mut rest = &stream[..];
    let mut cut = cuts.iter().cycle();
    while !rest.is_empty() {
        let n = (*cut.next().unwrap()).min(rest.len());
        got.extend(feed(&rest[..n]).into_iter().map(Result::unwrap));
        rest = &rest[n..];
    }
    got
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 1000, ..ProptestConfig::default() })]

    #[test]
    fn every_body_round_trips_as_a_datagram(env in envelope()) {
        let bytes = encode(&env).unwrap();
        prop_assert!(bytes.len() <= MAX_MESSAGE_LEN);
        prop_assert_eq!(decode(&bytes).unwrap(), env.clone());
        let head = peek(&bytes).unwrap();
        prop_assert_eq!(head.kind, env.body.kind());
        prop_assert_eq!(head.seq, env.header.seq);
        prop_assert_eq!(head.sender, env.header.sender.as_str());
        prop_assert_eq!(head.channel, env.header.channel.as_str());
        let region = signed_region(&bytes, &env).unwrap();
        prop_assert!(region.len() < bytes.len());
        prop_assert_eq!(region, &bytes[..region.len()]);
    }

    #[test]
    fn messages_round_trip_through_stream_framing(
        envs in vec(envelope(), 1..6),
        cuts in vec(1usize..64, 1..40),
    ) {
        let mut dec = StreamDecoder::new();
        let got = through_chunks(&envs, &cuts, write_stream_frame, |bytes| {
            dec.push(bytes);
            std::iter::from_fn(|| dec.next_message()).collect()
        });
        prop_assert_eq!(got, envs);
    }

    #[test]
    fn messages_round_trip_through_serial_framing(
        envs in vec(envelope(), 1..6),
        cuts in vec(1usize..64, 1..40),
    ) {
        let mut dec = SerialDecoder::new();
        let got = through_chunks(&envs, &cuts, write_serial_frame, |bytes| {
            dec.push(bytes);
            std::iter::from_fn(|| dec.next_message()).collect()
        });
        prop_assert_eq!(got, envs);
    }

    #[test]
    fn cobs_round_trips_any_bytes(data in vec(any::<u8>(), 0..2000)) {
        let mut enc = Vec::new();
        framing::cobs_encode(&data, &mut enc);
        prop_assert!(!enc.contains(&0));
        prop_assert_eq!(framing::cobs_decode(&enc).unwrap(), data);
    }
}

/// One fixture per body kind, so a new kind cannot be added without a
/// round-trip test through every framing.
fn one_of_each() -> Vec<Body> {
    let mut runner = proptest::test_runner::TestRunner::deterministic();
    let strategy = body();
    let mut seen = std::collections::BTreeMap::new();
    for _ in 0..20_000 {
        let b = strategy.new_tree(&mut runner).unwrap().current();
        seen.entry(b.kind()).or_insert(b);
    }
    seen.into_values().collect()
}

#[test]
fn every_known_kind_round_trips_through_each_framing() {
    let bodies = one_of_each();
    let known = (0..=255u64).filter(|&k| Body::is_known(k)).count();
    assert_eq!(bodies.len(), known, "the generator covers every body kind");
    for body in bodies {
        let env = Envelope::new(
            Header {
                seq: 1,
                stamp_us: 2,
                sender: "gcs".into(),
                destination: "robot_1".into(),
                channel: "joy/0".into(),
            },
            body,
        );
        assert_eq!(
            decode(&encode(&env).unwrap()).unwrap(),
            env,
            "datagram {}",
            env.body.name()
        );
        let mut s = Vec::new();
        write_stream_frame(&env, &mut s).unwrap();
        let mut sd = StreamDecoder::new();
        sd.push(&s);
        assert_eq!(
            sd.next_message(),
            Some(Ok(env.clone())),
            "stream {}",
            env.body.name()
        );
        let mut r = Vec::new();
        write_serial_frame(&env, &mut r).unwrap();
        let mut rd = SerialDecoder::new();
        rd.push(&r);
        assert_eq!(
            rd.next_message(),
            Some(Ok(env.clone())),
            "serial {}",
            env.body.name()
        );
    }
}

/// Telemetry in the shape `fields` elements long (11: before the stale
/// count, 12: before the velocity source), built by hand as an older agent
/// wrote it, with the stale count 7 when it has one.
fn older_telemetry(fields: u8) -> Vec<u8> {
    let env = Envelope::new(
        Header {
            sender: "robot_1".into(),
            ..Header::default()
        },
        Body::Telemetry(telemetry_with(7, VelocitySource::Measured)),
    );
    let bytes = encode(&env).unwrap();
    // Body: [pose .. mission, stale, velocity_source] -> keep the first
    // `fields` elements and fix the array length (0x9d = 13 elements).
    let at = bytes.iter().position(|b| *b == 0x9d).unwrap();
    let mut old = bytes.clone();
    old[at] = 0x90 | fields;
    // [..., stale 0x07, velocity source 0x01, auth nil]
    let tail = old.len() - 3;
    assert_eq!(&old[tail..], &[0x07, 0x01, 0xc0]);
    old.drain(tail + usize::from(fields - 11)..old.len() - 1);
    old
}

fn telemetry_with(stale: u32, velocity_source: VelocitySource) -> Telemetry {
    Telemetry {
        pose: Pose::default(),
        velocity: Velocity::default(),
        mode: ControlMode::Idle,
        channel: String::new(),
        computation: Computation::Onboard,
        failsafe: FailsafeState::Ok,
        health: Health::Ok,
        battery: None,
        position_quality: 1.0,
        actuators: vec![],
        mission: None,
        stale,
        velocity_source,
        safety: None,
    }
}

#[test]
fn telemetry_from_before_the_stale_count_still_decodes() {
    // Telemetry as version 1 first defined it: 11 fields, no stale count.
    let Body::Telemetry(t) = decode(&older_telemetry(11)).unwrap().body else {
        panic!("not telemetry")
    };
    assert_eq!(t, telemetry_with(0, VelocitySource::Commanded));
}

#[test]
fn telemetry_from_before_the_velocity_source_reads_as_commanded() {
    // 12 fields: the stale count, no velocity source.
    let Body::Telemetry(t) = decode(&older_telemetry(12)).unwrap().body else {
        panic!("not telemetry")
    };
    assert_eq!(t, telemetry_with(7, VelocitySource::Commanded));
}

#[test]
fn telemetry_without_a_safety_report_keeps_its_old_bytes_and_one_with_it_round_trips() {
    // No report: the 13-element array of before (older_telemetry relies
    // on it too), which reads back as no report.
    let plain = telemetry_with(7, VelocitySource::Measured);
    let env = Envelope::new(Header::default(), Body::Telemetry(plain.clone()));
    let bytes = encode(&env).unwrap();
    assert!(bytes.contains(&0x9d), "13 fields");
    assert!(!bytes.contains(&0x9e), "not 14");
    let reported = Telemetry {
        safety: Some(SafetyReport {
            state: SafetyState::Off,
            arena: 3,
            intervention: Intervention::Separation,
            counts: InterventionCounts {
                separation: 2,
                ..InterventionCounts::default()
            },
            radius: 0.12,
            position_error: 0.04,
        }),
        ..plain
    };
    let env = Envelope::new(Header::default(), Body::Telemetry(reported.clone()));
    let bytes = encode(&env).unwrap();
    assert!(bytes.contains(&0x9e), "14 fields");
    assert_eq!(decode(&bytes).unwrap(), env);
    // A bound that is no distance grows nobody's disc: refused.
    for error in [f64::NAN, -0.1, f64::INFINITY] {
        let mut bad = reported.clone();
        if let Some(s) = bad.safety.as_mut() {
            s.position_error = error;
        }
        assert!(Body::Telemetry(bad).validate().is_err(), "{error}");
    }
}

#[test]
fn arenas_that_a_robot_could_not_use_are_refused() {
    let square = |x: f64| {
        vec![
            Point { x, y: 0.0 },
            Point { x: x + 1.0, y: 0.0 },
            Point { x: x + 1.0, y: 1.0 },
            Point { x, y: 1.0 },
        ]
    };
    let good = Arena {
        robot: "robot_1".into(),
        id: 1,
        enabled: true,
        boundary: square(0.0),
        keep_out: vec![square(0.2)],
        slow_zones: vec![],
        margin: 0.05,
    };
    let check = |a: &Arena| Body::Arena(a.clone()).validate();
    assert!(check(&good).is_ok());
    let mut bad = good.clone();
    bad.margin = -0.1;
    assert!(check(&bad).is_err(), "negative margin");
    let mut bad = good.clone();
    bad.margin = f64::NAN;
    assert!(check(&bad).is_err(), "NaN margin");
    let mut bad = good.clone();
    bad.boundary.swap(1, 2);
    assert!(check(&bad).is_err(), "a bow tie");
    let mut bad = good.clone();
    bad.boundary.clear();
    assert!(check(&bad).is_err(), "keep-outs without a boundary");
    let mut bad = good.clone();
    bad.keep_out = vec![square(0.0); MAX_KEEP_OUTS + 1];
    assert!(check(&bad).is_err(), "too many keep-outs");
    let mut bad = good.clone();
    bad.slow_zones = vec![SlowZone {
        polygon: square(0.0),
        max_speed: -1.0,
    }];
    assert!(check(&bad).is_err(), "negative speed cap");
    let cleared = Arena {
        boundary: vec![],
        keep_out: vec![],
        ..good
    };
    assert!(cleared.is_empty() && check(&cleared).is_ok(), "no arena");
}

#[test]
fn the_largest_arena_and_neighbour_list_fit_one_datagram() {
    let ring = |n: usize, r: f64| -> Vec<Point> {
        (0..n)
            .map(|i| {
                let a = i as f64 / n as f64 * std::f64::consts::TAU;
                // Coordinates that need a full float64 each.
                Point {
                    x: 1_000.123_456_789 + r * a.cos(),
                    y: -1_000.987_654_321 + r * a.sin(),
                }
            })
            .collect()
    };
    let arena = Arena {
        robot: "r".repeat(MAX_NAME_LEN),
        id: u32::MAX,
        enabled: true,
        boundary: ring(MAX_BOUNDARY_VERTICES, 90.0),
        keep_out: vec![ring(MAX_POLYGON_VERTICES, 1.0); MAX_KEEP_OUTS],
        slow_zones: vec![
            SlowZone {
                polygon: ring(MAX_POLYGON_VERTICES, 2.0),
                max_speed: 0.1,
            };
            MAX_SLOW_ZONES
        ],
        margin: 0.1,
    };
    let n = Neighbour {
        id: u16::MAX,
        x: 1.1,
        y: 2.2,
        z: 3.3,
        vx: 0.1,
        vy: 0.2,
        vz: 0.3,
        radius: 0.15,
        age_ms: u32::MAX,
        cooperative: true,
    };
    let neighbours = Neighbours {
        robot: "r".repeat(MAX_NAME_LEN),
        stamp_us: u64::MAX,
        robots: vec![n; MAX_NEIGHBOURS],
        obstacles: vec![Obstacle::Polygon(ring(MAX_POLYGON_VERTICES, 1.0)); MAX_OBSTACLES],
    };
    for body in [Body::Arena(arena), Body::Neighbours(neighbours)] {
        let env = Envelope::new(Header::default(), body);
        let bytes = encode(&env).unwrap();
        assert!(bytes.len() <= MAX_MESSAGE_LEN, "{} bytes", bytes.len());
        assert_eq!(decode(&bytes).unwrap(), env);
    }
}
