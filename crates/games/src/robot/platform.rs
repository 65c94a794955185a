//! The robot's platform, opened from the options, its traffic counted for the reports.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result};
use strata_nao::{LolaConfig, LolaPlatform};
use strata_rcssmj::platform::{RcssConfig, RcssPlatform, TruthSource};
use strata_rcssmj::referee::TeamNumbers;
use strata_robot::platform::{
    ActuatorOrders, ExternalLink, MotionFeedback, Platform, PlatformError, PlatformInfo,
    SensorFrame, SharedPlatform, TeamLink,
};
use strata_runtime::Time;

use super::{PlatformKind, RobotOptions, RobotOutput};

/// What the platform delivered.
#[derive(Debug, Default)]
pub(crate) struct PlatformCounters {
    pub(crate) sensor_frames: AtomicU64,
    pub(crate) camera_frames: AtomicU64,
    pub(crate) detections: AtomicU64,
    pub(crate) errors: AtomicU64,
    pub(crate) disconnected: Mutex<Option<String>>,
}

impl PlatformCounters {
    pub(crate) fn disconnected(&self) -> Option<String> {
        self.disconnected.lock().unwrap_or_else(PoisonError::into_inner).clone()
    }

    pub(crate) fn note<T>(&self, result: &Result<T, PlatformError>) {
        match result {
            Ok(_) => {}
            Err(PlatformError::Disconnected(reason)) => {
                self.errors.fetch_add(1, Ordering::Relaxed);
                self.disconnected
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .get_or_insert_with(|| reason.clone());
            }
            Err(_) => {
                self.errors.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
}

/// A platform whose traffic is counted for the robot's report.
pub(crate) struct Observed<P> {
    pub(crate) inner: P,
    pub(crate) counters: Arc<PlatformCounters>,
}

impl<P: Platform> Platform for Observed<P> {
    fn info(&self) -> PlatformInfo {
        self.inner.info()
    }

    fn read_sensors(&mut self, now: Time) -> Result<Option<SensorFrame>, PlatformError> {
        let result = self.inner.read_sensors(now);
        self.counters.note(&result);
        if let Ok(Some(frame)) = &result {
            self.counters.sensor_frames.fetch_add(1, Ordering::Relaxed);
            if let Some(camera) = &frame.camera {
                self.counters.camera_frames.fetch_add(1, Ordering::Relaxed);
                self.counters
                    .detections
                    .fetch_add(camera.detections.len() as u64, Ordering::Relaxed);
            }
        }
        result
    }

    fn read_motion(&mut self, now: Time) -> Result<MotionFeedback, PlatformError> {
        let result = self.inner.read_motion(now);
        self.counters.note(&result);
        result
    }

    fn write(&mut self, now: Time, orders: &ActuatorOrders) -> Result<(), PlatformError> {
        let result = self.inner.write(now, orders);
        // An order the body cannot execute (a NAO asked to walk) is the reactive layer's
        // business, not a platform failure.
        if !matches!(result, Err(PlatformError::Unsupported(_))) {
            self.counters.note(&result);
        }
        result
    }
}

/// The team and game-controller links a platform carries itself.
pub(crate) struct PlatformLinks {
    pub(crate) team_link: Option<Box<dyn TeamLink>>,
    pub(crate) game_controller: Box<dyn ExternalLink>,
    /// Where the links lead, for the start line.
    pub(crate) label: &'static str,
}

pub(crate) struct OpenPlatform {
    pub(crate) shared: SharedPlatform,
    pub(crate) info: PlatformInfo,
    pub(crate) counters: Arc<PlatformCounters>,
    /// Where the sensors come from, for the start line.
    pub(crate) source: String,
    pub(crate) links: Option<PlatformLinks>,
    pub(crate) nao: Option<Arc<Mutex<Observed<LolaPlatform>>>>,
    /// Where the robot really is, on platforms that know it (for the accuracy report only).
    pub(crate) truth: Option<TruthSource>,
    pub(crate) t1: Option<Arc<Mutex<Observed<RcssPlatform>>>>,
}

pub(crate) fn open_platform(opts: &RobotOptions) -> Result<OpenPlatform> {
    let counters = Arc::<PlatformCounters>::default();
    match opts.platform {
        PlatformKind::Sim => {
            let server =
                opts.server.clone().unwrap_or_else(|| strata_sim::net::DEFAULT_ADDR.to_owned());
            let robot = strata_sim::net::connect(
                server.as_str(),
                opts.team,
                opts.player,
                Duration::from_secs(5),
            )
            .with_context(|| format!("connecting to the simulator server at {server}"))?;
            let info = robot.welcome.info.clone();
            let shared: SharedPlatform = Arc::new(Mutex::new(Observed {
                inner: robot.platform,
                counters: Arc::clone(&counters),
            }));
            Ok(OpenPlatform {
                shared,
                info,
                counters,
                source: format!("simulator server {server}"),
                links: Some(PlatformLinks {
                    team_link: Some(Box::new(robot.team_link)),
                    game_controller: Box::new(robot.game_controller),
                    label: "simulator server",
                }),
                nao: None,
                truth: None,
                t1: None,
            })
        }
        PlatformKind::Nao => {
            let config = match &opts.lola_config {
                Some(path) => {
                    let text = std::fs::read_to_string(path)
                        .with_context(|| format!("reading {}", path.display()))?;
                    toml::from_str::<LolaConfig>(&text)
                        .with_context(|| format!("LoLA configuration {}", path.display()))?
                }
                None => LolaConfig::default(),
            };
            let lola = LolaPlatform::connect(&opts.socket, config)
                .with_context(|| format!("connecting to LoLA at {}", opts.socket.display()))?;
            let info = lola.info();
            let nao =
                Arc::new(Mutex::new(Observed { inner: lola, counters: Arc::clone(&counters) }));
            let shared: SharedPlatform = nao.clone();
            Ok(OpenPlatform {
                shared,
                info,
                counters,
                source: format!("LoLA {}", opts.socket.display()),
                links: None,
                nao: Some(nao),
                truth: None,
                t1: None,
            })
        }
        PlatformKind::Rcssservermj => {
            let mut config = match &opts.rcss_config {
                Some(path) => {
                    let text = std::fs::read_to_string(path)
                        .with_context(|| format!("reading {}", path.display()))?;
                    toml::from_str::<RcssConfig>(&text)
                        .with_context(|| format!("rcssservermj configuration {}", path.display()))?
                }
                None => RcssConfig::default(),
            };
            if opts.beam.is_some() {
                config.beam = opts.beam;
            }
            config.camera_seed = opts
                .seed
                .unwrap_or(100 * u64::from(opts.team) + u64::from(opts.player))
                .wrapping_add(1);
            let server = opts.server.clone().unwrap_or_else(|| RCSS_DEFAULT_ADDR.to_owned());
            let team_name = rcss_team_name(opts);
            let t1 = RcssPlatform::connect(&server, &team_name, opts.player, config)
                .with_context(|| format!("connecting a T1 to rcssservermj at {server}"))?;
            let info = t1.info();
            let referee = t1.referee_link(TeamNumbers::new(opts.team));
            let truth = t1.truth_source();
            let t1 = Arc::new(Mutex::new(Observed { inner: t1, counters: Arc::clone(&counters) }));
            let shared: SharedPlatform = t1.clone();
            Ok(OpenPlatform {
                shared,
                info,
                counters,
                source: format!("rcssservermj {server} as {team_name} #{}", opts.player),
                links: Some(PlatformLinks {
                    team_link: None,
                    game_controller: Box::new(referee),
                    label: "rcssservermj's referee",
                }),
                nao: None,
                truth: Some(truth),
                t1: Some(t1),
            })
        }
    }
}

/// Ends a NAO's run sitting, motors soft: a robot left standing without commands falls.
pub(crate) fn sit_down(nao: &Arc<Mutex<Observed<LolaPlatform>>>, out: &dyn RobotOutput) {
    let lock = || nao.lock().unwrap_or_else(PoisonError::into_inner);
    // Bound first: a guard in the `match` scrutinee would live through the arms and the
    // `busy` polls below would deadlock on it.
    let sitting = lock().inner.sit_down();
    match sitting {
        Ok(expected) => {
            let deadline = Instant::now() + expected + Duration::from_secs(5);
            while lock().inner.busy() && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(20));
            }
            // Seated, the motors go soft; a few LoLA cycles carry that out before we exit.
            lock().inner.relax();
            std::thread::sleep(Duration::from_millis(60));
        }
        Err(error) => out.note(&format!("could not sit down: {error}")),
    }
}

/// rcssservermj's default agent port.
pub(crate) const RCSS_DEFAULT_ADDR: &str = "127.0.0.1:60000";

pub(crate) fn rcss_team_name(opts: &RobotOptions) -> String {
    opts.team_name.clone().unwrap_or_else(|| format!("Strata{}", opts.team))
}
