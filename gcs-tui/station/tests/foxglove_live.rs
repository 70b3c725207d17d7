//! The Foxglove live view of a station in this process (`[foxglove] addr
//! = 127.0.0.1:0`, two simulated robots), with WebSocket clients speaking
//! `foxglove.websocket.v1` as Foxglove and Lichtblick do: the channels and
//! schemas advertised are a recording's, a robot sent on a mission is seen
//! moving on its pose topic and in the scene (with the simulated robots'
//! arena), and clients that send
//! garbage, flood the server with requests or never read do not stop it;
//! the station's log says who was cut and why; connections that never
//! finish their handshake are closed as newer ones come, so they pile up
//! neither in the station nor in the way of a viewer. Without the `foxglove`
//! feature, a station asked for the live view does not start, and says
//! which feature it lacks. Loopback only.

#![allow(clippy::unwrap_used)]

use std::net::SocketAddr;

use mech_station::ConfigFile;

/// A station's configuration on loopback ports nobody holds, with the live
/// view asked for.
fn config() -> ConfigFile {
    let mut config = ConfigFile::default();
    config.router.udp = SocketAddr::from(([127, 0, 0, 1], 0));
    config.router.tcp = Some(SocketAddr::from(([127, 0, 0, 1], 0)));
    config.foxglove.addr = Some(SocketAddr::from(([127, 0, 0, 1], 0)));
    config.log.dir = None;
    config
}

#[cfg(not(feature = "foxglove"))]
#[tokio::test]
async fn without_the_feature_a_station_asked_for_the_live_view_does_not_start() {
    use mech_station::{Launched, Recording};
    let Err(e) = Launched::start(&config(), Recording::Off).await else {
        panic!("a station started with a live view it does not have")
    };
    assert!(format!("{e:#}").contains("feature `foxglove`"), "{e:#}");
}

#[cfg(feature = "foxglove")]
#[path = "support/foxglove.rs"]
mod foxglove;

#[cfg(feature = "foxglove")]
mod live {
    use std::path::Path;
    use std::time::{Duration, Instant};

    use mech_control::script::ScriptOutcome;
    use mech_core::record::schema;
    use mech_station::client::{AttachOptions, attach_stream, run_script};
    use mech_station::logging::{self, LogConfig};
    use mech_station::serve::spawn_demo;
    use mech_station::wire::Streams;
    use mech_station::{Launched, Recording, Station};

    use super::foxglove::{Client, Got, entity_ids, flood, garbage, position};

    /// Runs a script attached to the station, as `mech-gcs --attach
    /// --script` would; panics if it fails.
    async fn script(station: &Station, source: &str) {
        let opts = AttachOptions {
            operator: Some("test".into()),
            key: None,
            stream: Streams {
                snapshots: false,
                log: false,
                events: true,
            },
        };
        let mut attached = attach_stream(station.attach_local(), opts).await.unwrap();
        let mut out = Vec::new();
        let outcome = run_script(&mut attached, source, &mut out).await;
        assert!(
            matches!(outcome, ScriptOutcome::Passed { .. }),
            "{outcome:?}: {}",
            String::from_utf8_lossy(&out)
        );
    }

    /// The station's log files in `dir`, waiting (up to 20 s) until
    /// `needle` is in them.
    async fn log_with(dir: &Path, needle: &str) -> String {
        let deadline = Instant::now() + Duration::from_secs(20);
        loop {
            let text: String = std::fs::read_dir(dir)
                .into_iter()
                .flatten()
                .flatten()
                .filter(|e| e.file_name().to_string_lossy().starts_with("mech-gcs.log"))
                .filter_map(|e| std::fs::read_to_string(e.path()).ok())
                .collect();
            if text.contains(needle) || Instant::now() > deadline {
                return text;
            }
            tokio::time::sleep(Duration::from_millis(200)).await;
        }
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn the_live_view_shows_the_fleet_moving_and_bad_clients_do_not_hurt_it() {
        let logs = tempfile::tempdir().unwrap();
        let log = LogConfig {
            dir: Some(logs.path().to_path_buf()),
            ..LogConfig::default()
        };
        let _log = logging::init(&log, None).unwrap();
        let launched = Launched::start(&super::config(), Recording::Off)
            .await
            .unwrap();
        let station = launched.station().clone();
        spawn_demo(&station, 2).await.unwrap();
        let ws = launched.live_view().expect("the live view runs");
        assert_eq!(
            launched.describe(),
            format!("not recording; Foxglove live view on ws://{ws}")
        );
        let _flooder = flood(ws).await;
        garbage(ws).await;
        // A viewer reads all along, as Foxglove does (one that does not
        // read for 10 s is cut): the mission is sent while it reads.
        let mut viewer = Client::connect(ws).await;
        super::foxglove::check_channels(&mut viewer).await;
        viewer.subscribe(1, &schema::pose_topic("robot_1")).await;
        viewer.subscribe(2, schema::SCENE).await;
        let mission = script(
            &station,
            "wait connected robot_1 20s\nwaypoint robot_1 3.2,2.2 0.6,2.2 0.6,0.6 3.2,0.6 loop\n\
             send robot_1\nroute robot_1 wp/gcs\nwait route robot_1 wp/gcs 20s\n",
        );
        let watch = async {
            let mut first: Option<(f64, f64)> = None;
            let mut moved = 0.0f64;
            let mut last_ns = 0;
            let mut scene_ids = Vec::new();
            let deadline = Instant::now() + Duration::from_secs(90);
            while moved < 0.5 || !scene_ids.iter().any(|i: &String| i == "mission/robot_1") {
                assert!(
                    Instant::now() < deadline,
                    "robot_1 moved {moved:.2} m; scene {scene_ids:?}"
                );
                match viewer.next(Duration::from_secs(5)).await {
                    Some(Got::Data { sub: 1, ns, msg }) => {
                        assert_eq!(msg["frame_id"], "world");
                        assert!(ns >= last_ns, "time goes forward");
                        last_ns = ns;
                        let p = position(&msg);
                        let p0 = *first.get_or_insert(p);
                        moved = moved.max(((p.0 - p0.0).powi(2) + (p.1 - p0.1).powi(2)).sqrt());
                    }
                    Some(Got::Data { sub: 2, msg, .. }) => scene_ids = entity_ids(&msg),
                    Some(Got::Closed) => panic!("the live view closed the viewer"),
                    _ => {}
                }
            }
            scene_ids
        };
        let ((), scene_ids) = tokio::join!(mission, watch);
        assert!(scene_ids.contains(&"robot/robot_1".to_string()));
        assert!(scene_ids.contains(&"robot/robot_2".to_string()));
        // The simulated robots' arena, drawn as a recording draws it.
        assert!(
            scene_ids.contains(&"arena/boundary".to_string()),
            "{scene_ids:?}"
        );
        // The station still serves its operators.
        script(&station, "wait connected robot_2 20s\nstatus\n").await;
        // The log says who was cut and why.
        let text = log_with(logs.path(), "too many bad requests").await;
        assert!(text.contains("Foxglove live view listening"), "{text}");
        assert!(text.contains("too many bad requests"), "{text}");
        assert!(text.contains("Foxglove handshake refused"), "{text}");
        launched.shutdown().await;
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn connections_that_never_finish_their_handshake_are_closed_as_newer_ones_come() {
        use futures::future::join_all;
        use tokio::io::AsyncReadExt;
        use tokio::net::TcpStream;

        let launched = Launched::start(&super::config(), Recording::Off)
            .await
            .unwrap();
        let ws = launched.live_view().expect("the live view runs");
        // A stranger's connections that say nothing, well within the
        // handshake's 5 s.
        let mut idle = Vec::new();
        for _ in 0..100 {
            idle.push(TcpStream::connect(ws).await.unwrap());
        }
        let closed = join_all(idle.iter_mut().map(|s| async move {
            let mut b = [0u8; 64];
            matches!(
                tokio::time::timeout(Duration::from_millis(1500), s.read(&mut b)).await,
                Ok(Ok(0) | Err(_))
            )
        }))
        .await;
        let open = closed.iter().filter(|c| !**c).count();
        // 16 places for handshakes, 4 of them for one address.
        assert!(open <= 4, "{open} of 100 idle connections still open");
        assert!(
            closed[..closed.len() - 4].iter().all(|c| *c),
            "the oldest are closed first"
        );
        // A viewer still gets in, and is shown the fleet's channels.
        let mut viewer = super::foxglove::Client::connect(ws).await;
        let scene = viewer.channel(schema::SCENE).await;
        assert_eq!(scene["schemaName"], schema::SCENE_UPDATE);
        launched.shutdown().await;
    }
}
