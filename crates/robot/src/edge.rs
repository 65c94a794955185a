//! The platform at the edge of a robot's graph: the only modules that touch a [`Platform`].
//!
//! ```text
//! Platform ─▶ sensors ─frames (Queue)──▶ perception
//!                     └motion (Merge)──▶ actuation ─orders (Queue)─▶ actuators ─▶ Platform
//!                                            ▲                          │
//!                                            └────refusals (Queue)──────┘
//! Links ─▶ links_in ─inbox (Queue)─▶ planning ─outbox (Queue)─▶ links_out ─▶ Links
//! ```
//!
//! `sensors` reads the platform once per sensor period and publishes what it measured: the
//! sensor frame and the motion feedback (state and odometry). `actuators` writes the orders
//! actuation decides and sends back the ones the platform refuses. `links_in` takes what the
//! team and external links received once per planning period and wakes the planning layer
//! with it; `links_out` sends what planning composed. Everything between the edges is
//! computation on packages, so every module of the robot replays from a log. Every platform
//! plugs in the same way, as [`PlatformPorts`]: a platform object (the simulator server's
//! client, the NAO's LoLA socket, the T1 in rcssservermj) through [`add_platform_edge`], a
//! platform that is a module of the graph (the in-process simulator) with its own ports. Every
//! pair of links (the simulator's, UDP on a field, rcssservermj's referee) plugs in through
//! [`add_link_edge`].

use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use serde::{Deserialize, Serialize};
use strata_runtime::{
    Context, GraphBuilder, Input, Module, ModuleError, Output, Policy, PortName, Trigger,
};

use crate::command::Resource;
use crate::platform::{
    ActuatorOrders, ExternalLink, MotionFeedback, PlatformError, PlatformInfo, ReceivedPacket,
    SensorFrame, SharedPlatform, TeamLink, lock_platform,
};

/// Orders the platform refused (a NAO without a gait engine asked to walk): actuation tells the
/// reactive layer instead of the robot stopping.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OrderRefused {
    /// The body when the orders held a body order (a refused sequence must release it), else
    /// the head.
    pub resource: Resource,
    pub reason: String,
}

impl OrderRefused {
    /// The platform refused `orders` for `reason`.
    pub fn of(orders: &ActuatorOrders, reason: String) -> OrderRefused {
        let resource = if orders.body.is_some() { Resource::Body } else { Resource::Head };
        OrderRefused { resource, reason }
    }
}

/// The ports of the sensor source, declared once for the assembly and for replay.
#[derive(Clone, Copy, Debug)]
pub struct SensorPorts {
    pub frames: Output<SensorFrame>,
    pub motion: Output<MotionFeedback>,
}

impl SensorPorts {
    pub const FRAMES: PortName<SensorFrame> = PortName::new("frames");
    pub const MOTION: PortName<MotionFeedback> = PortName::new("motion");
}

/// The ports of the actuator sink.
#[derive(Clone, Copy, Debug)]
pub struct ActuatorPorts {
    pub orders: Input<ActuatorOrders>,
    pub refusals: Output<OrderRefused>,
}

impl ActuatorPorts {
    pub const ORDERS: PortName<ActuatorOrders> = PortName::new("orders");
    pub const REFUSALS: PortName<OrderRefused> = PortName::new("refusals");
    /// Orders actuation sent that the platform has not been given yet.
    pub const ORDER_QUEUE: usize = 16;
}

/// A platform as the robot's graph sees it: what it publishes and what it takes, whichever
/// modules do it — a robot's own `sensors` and `actuators` over a [`Platform`], or a module
/// that is the platform of several robots (the in-process simulator).
#[derive(Clone, Debug)]
pub struct PlatformPorts {
    pub info: PlatformInfo,
    pub frames: Output<SensorFrame>,
    pub motion: Output<MotionFeedback>,
    pub orders: Input<ActuatorOrders>,
    pub refusals: Output<OrderRefused>,
}

impl PlatformPorts {
    /// Declares, on a module that is the platform of several robots (a simulator), the ports
    /// that serve one of them: `{prefix}/frames`, `{prefix}/motion`, `{prefix}/orders` and
    /// `{prefix}/refusals`. Orders are not a trigger: they wait for the module's next step.
    pub fn serve(
        p: &mut strata_runtime::Ports<'_>,
        prefix: &str,
        info: PlatformInfo,
    ) -> PlatformPorts {
        let name = |port: &str| format!("{prefix}/{port}");
        PlatformPorts {
            info,
            frames: p.output(&name(SensorPorts::FRAMES.name())),
            motion: p.output(&name(SensorPorts::MOTION.name())),
            orders: p.optional_input(
                &name(ActuatorPorts::ORDERS.name()),
                Policy::queue(ActuatorPorts::ORDER_QUEUE),
            ),
            refusals: p.output(&name(ActuatorPorts::REFUSALS.name())),
        }
    }
}

/// Hands every order waiting on `orders` to `write` (the platform), and sends the ones it
/// refuses as unsupported back on `refusals` so actuation releases them; any other error ends
/// the cycle.
pub fn write_orders(
    ctx: &mut Context<'_>,
    orders: Input<ActuatorOrders>,
    refusals: Output<OrderRefused>,
    mut write: impl FnMut(&ActuatorOrders) -> Result<(), PlatformError>,
) -> Result<(), ModuleError> {
    for package in ctx.drain(orders) {
        let orders = package.value;
        match write(&orders) {
            Ok(()) => {}
            Err(PlatformError::Unsupported(reason)) => {
                ctx.send(refusals, OrderRefused::of(&orders, reason));
            }
            Err(other) => return Err(Box::new(other)),
        }
    }
    Ok(())
}

/// Where a robot's platform comes from.
pub enum RobotPlatform {
    /// A platform object: the robot's own edge modules read and write it
    /// ([`add_platform_edge`]).
    Shared(SharedPlatform),
    /// A module already in the graph publishes the robot's frames and takes its orders.
    Module(PlatformPorts),
}

impl std::fmt::Debug for RobotPlatform {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RobotPlatform::Shared(_) => f.write_str("RobotPlatform::Shared"),
            RobotPlatform::Module(ports) => {
                f.debug_tuple("RobotPlatform::Module").field(ports).finish()
            }
        }
    }
}

impl RobotPlatform {
    pub fn info(&self) -> PlatformInfo {
        match self {
            RobotPlatform::Shared(platform) => lock_platform(platform).info(),
            RobotPlatform::Module(ports) => ports.info.clone(),
        }
    }

    /// The platform's ports, adding the robot's own edge modules (named after `prefix`,
    /// reading every `period`) for a platform object. A platform module sends frames at its
    /// own rate, which `period` does not change: the robot's perception runs on each of them
    /// (the simulator's rate is `strata_sim::config::TimingConfig::sensor_period`).
    pub fn into_ports(
        self,
        graph: &mut GraphBuilder,
        prefix: &str,
        period: std::time::Duration,
    ) -> PlatformPorts {
        match self {
            RobotPlatform::Module(ports) => ports,
            RobotPlatform::Shared(platform) => {
                let info = lock_platform(&platform).info();
                let (sensors, actuators) = add_platform_edge(graph, prefix, platform, period);
                PlatformPorts {
                    info,
                    frames: sensors.frames,
                    motion: sensors.motion,
                    orders: actuators.orders,
                    refusals: actuators.refusals,
                }
            }
        }
    }
}

/// Reads the platform every sensor period.
pub struct SensorSource {
    platform: SharedPlatform,
    ports: SensorPorts,
    malformed_frames: u64,
}

impl std::fmt::Debug for SensorSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SensorSource")
            .field("malformed_frames", &self.malformed_frames)
            .finish_non_exhaustive()
    }
}

impl Module for SensorSource {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        let now = ctx.now();
        let (frame, motion) = {
            let mut platform = lock_platform(&self.platform);
            let frame = platform.read_sensors(now);
            (frame, platform.read_motion(now))
        };
        match frame {
            Ok(Some(frame)) => {
                let stamp = frame.stamp;
                ctx.send_stamped(self.ports.frames, frame, stamp);
            }
            Ok(None) => {}
            // One garbled frame costs one cycle, not the robot.
            Err(PlatformError::Malformed(reason)) => {
                self.malformed_frames += 1;
                tracing::warn!(module = ctx.module_name(), %reason, total = self.malformed_frames, "malformed sensor frame skipped");
            }
            Err(error) => return Err(Box::new(error)),
        }
        let motion = motion?;
        ctx.send_stamped(self.ports.motion, motion, motion.stamp);
        Ok(())
    }
}

/// Writes actuation's orders to the platform.
pub struct ActuatorSink {
    platform: SharedPlatform,
    ports: ActuatorPorts,
}

impl std::fmt::Debug for ActuatorSink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ActuatorSink").finish_non_exhaustive()
    }
}

impl Module for ActuatorSink {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        let now = ctx.now();
        write_orders(ctx, self.ports.orders, self.ports.refusals, |orders| {
            lock_platform(&self.platform).write(now, orders)
        })
    }
}

/// The names of a platform's edge modules.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EdgeModules {
    pub sensors: String,
    pub actuators: String,
    pub links_in: String,
    pub links_out: String,
}

impl EdgeModules {
    pub fn new(prefix: &str) -> EdgeModules {
        EdgeModules {
            sensors: format!("{prefix}/sensors"),
            actuators: format!("{prefix}/actuators"),
            links_in: format!("{prefix}/links_in"),
            links_out: format!("{prefix}/links_out"),
        }
    }
}

/// Adds the sensor source (reading `platform` every `period`) and the actuator sink of one
/// robot, named after `prefix` (`"blue/3"` gives `"blue/3/sensors"` and `"blue/3/actuators"`).
pub fn add_platform_edge(
    graph: &mut GraphBuilder,
    prefix: &str,
    platform: SharedPlatform,
    period: std::time::Duration,
) -> (SensorPorts, ActuatorPorts) {
    let names = EdgeModules::new(prefix);
    let source_platform = platform.clone();
    let sensors = graph.add(&names.sensors, |p| {
        p.trigger(Trigger::every(period));
        p.real_time();
        let ports = SensorPorts {
            frames: p.output(SensorPorts::FRAMES),
            motion: p.output(SensorPorts::MOTION),
        };
        (SensorSource { platform: source_platform, ports, malformed_frames: 0 }, ports)
    });
    let actuators = graph.add(&names.actuators, |p| {
        let ports = ActuatorPorts {
            orders: p.input(ActuatorPorts::ORDERS, Policy::queue(ActuatorPorts::ORDER_QUEUE)),
            refusals: p.output(ActuatorPorts::REFUSALS),
        };
        p.trigger(Trigger::on_any([ports.orders.into()]));
        p.real_time();
        (ActuatorSink { platform, ports }, ports)
    });
    (sensors, actuators)
}

/// What the robot's links received since the previous planning cycle, oldest first.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LinkInbox {
    /// Teammates' messages.
    pub team: Vec<ReceivedPacket>,
    /// The external device's packets (the GameController's).
    pub external: Vec<ReceivedPacket>,
}

/// What the planning layer sends in one cycle.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LinkOutbox {
    /// A message to the teammates.
    pub team: Option<Vec<u8>>,
    /// A packet to the external device (a GameController return packet).
    pub external: Option<Vec<u8>>,
}

/// The ports of the links' source.
#[derive(Clone, Copy, Debug)]
pub struct LinkSourcePorts {
    pub inbox: Output<LinkInbox>,
}

impl LinkSourcePorts {
    pub const INBOX: PortName<LinkInbox> = PortName::new("inbox");
}

/// The ports of the links' sink.
#[derive(Clone, Copy, Debug)]
pub struct LinkSinkPorts {
    pub outbox: Input<LinkOutbox>,
}

impl LinkSinkPorts {
    pub const OUTBOX: PortName<LinkOutbox> = PortName::new("outbox");
}

/// A robot's links to its teammates and to an external device, either of which it may lack.
#[derive(Default)]
pub struct Links {
    pub team: Option<Box<dyn TeamLink>>,
    pub external: Option<Box<dyn ExternalLink>>,
}

impl std::fmt::Debug for Links {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Links")
            .field("team", &self.team.is_some())
            .field("external", &self.external.is_some())
            .finish()
    }
}

impl Links {
    /// A team link and an external link, either of which the robot may lack.
    pub fn new(team: Option<Box<dyn TeamLink>>, external: Option<Box<dyn ExternalLink>>) -> Links {
        Links { team, external }
    }
}

/// A robot's links as a module of the graph serves them (the in-process simulator, which is
/// every robot's radio and GameController): what they received, published by that module as
/// it arrives, and what the robot sends, which it takes at its next step.
#[derive(Clone, Copy, Debug)]
pub struct LinkPorts {
    pub received: Output<LinkInbox>,
    pub sent: Input<LinkOutbox>,
    /// Whether the robot uses its team link: a team playing without coordination has a radio
    /// it neither listens to nor sends on.
    pub team: bool,
}

impl LinkPorts {
    pub const RECEIVED: PortName<LinkInbox> = PortName::new("received");
    pub const SENT: PortName<LinkOutbox> = PortName::new("sent");
    /// What one robot sends between two steps of the serving module: its planning layer sends
    /// at most once per cycle.
    pub const SENT_QUEUE: usize = 16;

    /// Declares, on a module that serves the links of several robots, the ports that serve one
    /// of them: `{prefix}/received` and `{prefix}/sent`. What a robot sends is not a trigger:
    /// it waits for the module's next step.
    pub fn serve(p: &mut strata_runtime::Ports<'_>, prefix: &str) -> LinkPorts {
        LinkPorts {
            received: p.output(&format!("{prefix}/{}", Self::RECEIVED.name())),
            sent: p.optional_input(
                &format!("{prefix}/{}", Self::SENT.name()),
                Policy::queue(Self::SENT_QUEUE),
            ),
            team: true,
        }
    }
}

/// Where a robot's links come from.
pub enum RobotLinks {
    /// Link objects: the robot's own `links_in` and `links_out` read and write them.
    Shared(Links),
    /// A module already in the graph serves them: the robot's `links_in` gathers what it
    /// publishes once per planning period, `links_out` passes on what planning sends.
    Module(LinkPorts),
}

impl Default for RobotLinks {
    /// No links at all (a lone robot).
    fn default() -> RobotLinks {
        RobotLinks::Shared(Links::default())
    }
}

impl std::fmt::Debug for RobotLinks {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RobotLinks::Shared(links) => f.debug_tuple("RobotLinks::Shared").field(links).finish(),
            RobotLinks::Module(ports) => f.debug_tuple("RobotLinks::Module").field(ports).finish(),
        }
    }
}

impl RobotLinks {
    /// The same links without the team link: the robot neither hears nor tells its teammates.
    pub fn without_team(self) -> RobotLinks {
        match self {
            RobotLinks::Shared(links) => RobotLinks::Shared(Links { team: None, ..links }),
            RobotLinks::Module(ports) => RobotLinks::Module(LinkPorts { team: false, ..ports }),
        }
    }
}

type SharedLinks = Arc<Mutex<Links>>;

fn lock_links(links: &SharedLinks) -> MutexGuard<'_, Links> {
    // A panic elsewhere with the lock held leaves the links as usable as before it.
    links.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Takes what the links received, once per planning period, and wakes the planning layer with
/// it (an empty inbox too: the layer runs at this module's rate).
pub struct LinkSource {
    links: SharedLinks,
    ports: LinkSourcePorts,
    errors: u64,
}

impl std::fmt::Debug for LinkSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LinkSource").field("errors", &self.errors).finish_non_exhaustive()
    }
}

impl Module for LinkSource {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        let now = ctx.now();
        let mut inbox = LinkInbox::default();
        let (team, external) = {
            let mut links = lock_links(&self.links);
            let team = links.team.as_mut().map(|link| link.receive(now));
            (team, links.external.as_mut().map(|link| link.receive(now)))
        };
        // A failing link costs what it would have received, not the robot: planning falls back
        // to what it knows.
        for (link, received, into) in
            [("team link", team, &mut inbox.team), ("external link", external, &mut inbox.external)]
        {
            match received {
                Some(Ok(packets)) => *into = packets,
                Some(Err(error)) => {
                    self.errors += 1;
                    tracing::warn!(module = ctx.module_name(), %error, total = self.errors, "{link}");
                }
                None => {}
            }
        }
        ctx.send(self.ports.inbox, inbox);
        Ok(())
    }
}

/// Sends what the planning layer composed.
pub struct LinkSink {
    links: SharedLinks,
    ports: LinkSinkPorts,
    errors: u64,
}

impl std::fmt::Debug for LinkSink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LinkSink").field("errors", &self.errors).finish_non_exhaustive()
    }
}

impl Module for LinkSink {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        let now = ctx.now();
        for package in ctx.drain(self.ports.outbox) {
            let LinkOutbox { team, external } = package.value;
            let mut links = lock_links(&self.links);
            if let (Some(bytes), Some(link)) = (team, links.team.as_mut())
                && let Err(error) = link.send(now, &bytes)
            {
                self.errors += 1;
                tracing::warn!(module = ctx.module_name(), %error, "team message not sent");
            }
            if let (Some(bytes), Some(link)) = (external, links.external.as_mut())
                && let Err(error) = link.send(now, &bytes)
            {
                self.errors += 1;
                tracing::debug!(module = ctx.module_name(), %error, "status packet not sent");
            }
        }
        Ok(())
    }
}

/// Gathers what a module serving the robot's links published since the previous planning
/// period and wakes the planning layer with it, as [`LinkSource`] does for link objects.
#[derive(Debug)]
pub struct LinkGather {
    received: Input<LinkInbox>,
    team: bool,
    ports: LinkSourcePorts,
}

impl LinkGather {
    pub const RECEIVED: PortName<LinkInbox> = LinkPorts::RECEIVED;
}

impl Module for LinkGather {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        let mut inbox = ctx.take(self.received).map(|package| package.value).unwrap_or_default();
        if !self.team {
            inbox.team.clear();
        }
        ctx.send(self.ports.inbox, inbox);
        Ok(())
    }
}

/// Passes what the planning layer sends on to the module serving the robot's links.
#[derive(Debug)]
pub struct LinkPass {
    ports: LinkSinkPorts,
    sent: Output<LinkOutbox>,
    team: bool,
}

impl LinkPass {
    pub const SENT: PortName<LinkOutbox> = LinkPorts::SENT;
}

impl Module for LinkPass {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        for package in ctx.drain(self.ports.outbox) {
            let mut outbox = package.value;
            if !self.team {
                outbox.team = None;
            }
            if outbox.team.is_some() || outbox.external.is_some() {
                ctx.send(self.sent, outbox);
            }
        }
        Ok(())
    }
}

/// Adds the links' source (every `period`, the planning layer's) and sink of one robot, named
/// `{prefix}/links_in` and `{prefix}/links_out`: over link objects they receive and send, over
/// a module that serves the links they gather what it published and pass on what to send.
pub fn add_link_edge(
    graph: &mut GraphBuilder,
    prefix: &str,
    links: RobotLinks,
    period: std::time::Duration,
) -> (LinkSourcePorts, LinkSinkPorts) {
    match links {
        RobotLinks::Shared(links) => add_link_objects(graph, prefix, links, period),
        RobotLinks::Module(served) => {
            let names = EdgeModules::new(prefix);
            let source = graph.add(&names.links_in, |p| {
                p.trigger(Trigger::every(period));
                // Merged, never dropped: however many steps of the serving module fall in one
                // planning period, every packet reaches planning.
                let received = p.input(
                    LinkGather::RECEIVED,
                    Policy::merge(|into: &mut LinkInbox, more: LinkInbox| {
                        into.team.extend(more.team);
                        into.external.extend(more.external);
                    }),
                );
                let ports = LinkSourcePorts { inbox: p.output(LinkSourcePorts::INBOX) };
                (LinkGather { received, team: served.team, ports }, (ports, received))
            });
            let sink = graph.add(&names.links_out, |p| {
                let ports =
                    LinkSinkPorts { outbox: p.input(LinkSinkPorts::OUTBOX, Policy::queue(8)) };
                p.trigger(Trigger::on_any([ports.outbox.into()]));
                let sent = p.output(LinkPass::SENT);
                (LinkPass { ports, sent, team: served.team }, (ports, sent))
            });
            graph.connect(served.received, source.1);
            graph.connect(sink.1, served.sent);
            (source.0, sink.0)
        }
    }
}

fn add_link_objects(
    graph: &mut GraphBuilder,
    prefix: &str,
    links: Links,
    period: std::time::Duration,
) -> (LinkSourcePorts, LinkSinkPorts) {
    let names = EdgeModules::new(prefix);
    let links: SharedLinks = Arc::new(Mutex::new(links));
    let source_links = Arc::clone(&links);
    let source = graph.add(&names.links_in, |p| {
        p.trigger(Trigger::every(period));
        let ports = LinkSourcePorts { inbox: p.output(LinkSourcePorts::INBOX) };
        (LinkSource { links: source_links, ports, errors: 0 }, ports)
    });
    let sink = graph.add(&names.links_out, |p| {
        let ports = LinkSinkPorts { outbox: p.input(LinkSinkPorts::OUTBOX, Policy::queue(8)) };
        p.trigger(Trigger::on_any([ports.outbox.into()]));
        (LinkSink { links, ports, errors: 0 }, ports)
    });
    (source, sink)
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use strata_runtime::{HostConfig, LockstepHost, Time};

    use super::*;
    use crate::command::Resource;
    use crate::platform::{
        BodyMotionState, BodyOrder, HeadAngles, LinkError, Platform, PlatformInfo,
    };

    /// Every third frame garbled; odometry of 1 cm per read; refuses special sequences.
    struct Garbling {
        reads: u32,
        written: Arc<Mutex<Vec<ActuatorOrders>>>,
    }

    impl Platform for Garbling {
        fn info(&self) -> PlatformInfo {
            PlatformInfo {
                name: "garbling".into(),
                sensor_period: Duration::from_millis(10),
                camera_fov: 1.0,
                camera_range: 5.0,
                head_yaw_limits: (-2.0, 2.0),
                head_pitch_limits: (-0.5, 0.5),
                max_head_speed: 3.0,
                max_velocity: crate::geometry::Velocity::new(0.2, 0.1, 1.0),
                motions: Vec::new(),
                can_walk: true,
            }
        }

        fn read_sensors(&mut self, now: Time) -> Result<Option<SensorFrame>, PlatformError> {
            self.reads += 1;
            if self.reads.is_multiple_of(3) {
                return Err(PlatformError::Malformed("garbled".into()));
            }
            Ok(Some(SensorFrame { stamp: now, ..SensorFrame::default() }))
        }

        fn read_motion(&mut self, now: Time) -> Result<MotionFeedback, PlatformError> {
            Ok(MotionFeedback {
                stamp: now,
                body: BodyMotionState::Standing,
                head: HeadAngles::default(),
                head_settled: true,
                odometry: crate::geometry::Odometry { dx: 0.01, dy: 0.0, dtheta: 0.0 },
            })
        }

        fn write(&mut self, _: Time, orders: &ActuatorOrders) -> Result<(), PlatformError> {
            if let Some(BodyOrder::Special { .. }) = orders.body {
                return Err(PlatformError::Unsupported("no special sequences".into()));
            }
            self.written.lock().unwrap_or_else(PoisonError::into_inner).push(*orders);
            Ok(())
        }
    }

    /// Collects every package of one type.
    struct Collect<T: strata_runtime::Message> {
        input: Input<T>,
        seen: Arc<Mutex<Vec<T>>>,
    }

    impl<T: strata_runtime::Message> Module for Collect<T> {
        fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
            let packages = ctx.drain(self.input);
            let mut seen = self.seen.lock().unwrap_or_else(PoisonError::into_inner);
            seen.extend(packages.into_iter().map(|p| p.value));
            Ok(())
        }
    }

    fn collect<T: strata_runtime::Message>(
        graph: &mut GraphBuilder,
        name: &str,
        from: Output<T>,
    ) -> Arc<Mutex<Vec<T>>> {
        let seen = Arc::new(Mutex::new(Vec::new()));
        let input = graph.add(name, |p| {
            let input = p.input::<T>("in", Policy::queue(1024));
            p.trigger(Trigger::on_any([input.into()]));
            (Collect { input, seen: Arc::clone(&seen) }, input)
        });
        graph.connect(from, input);
        seen
    }

    fn taken<T: Clone>(seen: &Arc<Mutex<Vec<T>>>) -> Vec<T> {
        seen.lock().unwrap_or_else(PoisonError::into_inner).clone()
    }

    #[test]
    fn sensors_publish_frames_and_motion_and_skip_garbled_frames_actuators_write_or_refuse() {
        let written = Arc::new(Mutex::new(Vec::new()));
        let platform: SharedPlatform =
            Arc::new(Mutex::new(Garbling { reads: 0, written: Arc::clone(&written) }));
        let mut graph = GraphBuilder::new();
        let (sensors, actuators) =
            add_platform_edge(&mut graph, "r", platform, Duration::from_millis(10));
        let frames = collect(&mut graph, "frames", sensors.frames);
        let motion = collect(&mut graph, "motion", sensors.motion);
        let refusals = collect(&mut graph, "refusals", actuators.refusals);
        graph.external(actuators.orders);
        let mut host = LockstepHost::new(graph.build().expect("graph"), HostConfig::with_seed(1));
        let walk = ActuatorOrders {
            head: None,
            body: Some(BodyOrder::Walk { velocity: crate::geometry::Velocity::new(0.1, 0.0, 0.0) }),
        };
        let stand_up = ActuatorOrders {
            head: None,
            body: Some(BodyOrder::Special { motion: crate::platform::SpecialMotion::stand_up(0) }),
        };
        let at = |ms: u64| Time::from_nanos(ms * 1_000_000);
        host.inject(actuators.orders, walk, at(15), at(15)).expect("inject");
        host.inject(actuators.orders, stand_up, at(25), at(25)).expect("inject");
        host.run_for(Duration::from_millis(95)).expect("runs");

        // Reads at 0, 10, ..., 90 ms: the 3rd, 6th and 9th garbled and skipped, the robot going on.
        assert_eq!(taken(&frames).len(), 7);
        assert_eq!(taken(&motion).len(), 10);
        assert_eq!(*written.lock().unwrap_or_else(PoisonError::into_inner), vec![walk]);
        let refusals = taken(&refusals);
        assert_eq!(refusals.len(), 1);
        assert_eq!(refusals[0].resource, Resource::Body);
        assert!(refusals[0].reason.contains("special"), "{refusals:?}");
    }

    #[test]
    fn every_package_at_the_edge_has_a_positional_encoding_for_logs() {
        use strata_runtime::cdr::trace;
        // Without one a log falls back to a self-describing encoding Foxglove cannot read.
        assert!(trace::<SensorFrame>().is_ok());
        assert!(trace::<MotionFeedback>().is_ok());
        assert!(trace::<ActuatorOrders>().is_ok(), "{:?}", trace::<ActuatorOrders>());
        assert!(trace::<OrderRefused>().is_ok());
        assert!(trace::<LinkInbox>().is_ok());
        assert!(trace::<LinkOutbox>().is_ok());
    }

    /// A link that receives one packet per call and fails every fourth send.
    struct Counting {
        received: u32,
        sent: Arc<Mutex<Vec<Vec<u8>>>>,
    }

    impl TeamLink for Counting {
        fn send(&mut self, _: Time, payload: &[u8]) -> Result<(), crate::platform::LinkError> {
            let mut sent = self.sent.lock().unwrap_or_else(PoisonError::into_inner);
            sent.push(payload.to_vec());
            if sent.len().is_multiple_of(4) {
                return Err(LinkError::Closed("every fourth".into()));
            }
            Ok(())
        }

        fn receive(&mut self, now: Time) -> Result<Vec<ReceivedPacket>, LinkError> {
            self.received += 1;
            Ok(vec![ReceivedPacket { received: now, bytes: vec![self.received as u8] }])
        }
    }

    #[test]
    fn links_deliver_an_inbox_every_period_and_send_each_outbox_to_the_links_the_robot_has() {
        let sent = Arc::new(Mutex::new(Vec::new()));
        let links = Links {
            team: Some(Box::new(Counting { received: 0, sent: Arc::clone(&sent) })),
            external: None,
        };
        let mut graph = GraphBuilder::new();
        let (source, sink) =
            add_link_edge(&mut graph, "r", RobotLinks::Shared(links), Duration::from_millis(100));
        let inboxes = collect(&mut graph, "inboxes", source.inbox);
        graph.external(sink.outbox);
        let mut host = LockstepHost::new(graph.build().expect("graph"), HostConfig::with_seed(1));
        for i in 0..5u8 {
            let at = Time::from_nanos(50_000_000 + u64::from(i) * 100_000_000);
            // No external link: its packet is dropped, the team's is sent.
            let outbox = LinkOutbox { team: Some(vec![i]), external: Some(vec![99]) };
            host.inject(sink.outbox, outbox, at, at).expect("inject");
        }
        host.run_for(Duration::from_millis(450)).expect("runs");

        let inboxes = taken(&inboxes);
        assert_eq!(inboxes.len(), 5, "0, 100, ..., 400 ms");
        assert!(inboxes.iter().all(|inbox| inbox.team.len() == 1 && inbox.external.is_empty()));
        assert_eq!(inboxes[4].team[0].bytes, vec![5]);
        // The fourth send failed: the link went on with the fifth.
        assert_eq!(
            *sent.lock().unwrap_or_else(PoisonError::into_inner),
            vec![vec![0], vec![1], vec![2], vec![3], vec![4]]
        );
    }

    /// A module that serves one robot's links: every 30 ms it publishes one team packet and
    /// one external packet (numbered), and keeps what the robot sent.
    struct Radio {
        ports: LinkPorts,
        cycles: u8,
        sent: Arc<Mutex<Vec<LinkOutbox>>>,
    }

    impl Module for Radio {
        fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
            let sent = ctx.drain(self.ports.sent);
            self.sent
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .extend(sent.into_iter().map(|p| p.value));
            let packet = |bytes| vec![ReceivedPacket { received: ctx.now(), bytes }];
            let inbox = LinkInbox {
                team: packet(vec![self.cycles]),
                external: packet(vec![100 + self.cycles]),
            };
            ctx.send(self.ports.received, inbox);
            self.cycles += 1;
            Ok(())
        }
    }

    fn served_links(team: bool) -> (Vec<LinkInbox>, Vec<LinkOutbox>) {
        let sent = Arc::new(Mutex::new(Vec::new()));
        let mut graph = GraphBuilder::new();
        let ports = graph.add("radio", |p| {
            p.trigger(Trigger::every(Duration::from_millis(30)));
            let ports = LinkPorts::serve(p, "r");
            (Radio { ports, cycles: 0, sent: Arc::clone(&sent) }, ports)
        });
        let links = RobotLinks::Module(ports);
        let links = if team { links } else { links.without_team() };
        let (source, sink) = add_link_edge(&mut graph, "r", links, Duration::from_millis(100));
        let inboxes = collect(&mut graph, "inboxes", source.inbox);
        graph.external(sink.outbox);
        let mut host = LockstepHost::new(graph.build().expect("graph"), HostConfig::with_seed(1));
        let at = |ms: u64| Time::from_nanos(ms * 1_000_000);
        let both = LinkOutbox { team: Some(vec![1]), external: Some(vec![2]) };
        let team_only = LinkOutbox { team: Some(vec![3]), external: None };
        host.inject(sink.outbox, both, at(50), at(50)).expect("inject");
        host.inject(sink.outbox, team_only, at(150), at(150)).expect("inject");
        host.run_for(Duration::from_millis(450)).expect("runs");
        let sent = sent.lock().unwrap_or_else(PoisonError::into_inner).clone();
        (taken(&inboxes), sent)
    }

    #[test]
    fn links_a_module_serves_gather_everything_it_published_once_a_period_and_pass_on_what_planning_sends()
     {
        let (inboxes, sent) = served_links(true);
        assert_eq!(inboxes.len(), 5, "an inbox at 0, 100, ..., 400 ms, empty or not");
        // Published at 0, 30, ..., 390 ms: every packet in one of the inboxes, in order.
        let team: Vec<u8> =
            inboxes.iter().flat_map(|i| i.team.iter().map(|p| p.bytes[0])).collect();
        let external: Vec<u8> =
            inboxes.iter().flat_map(|i| i.external.iter().map(|p| p.bytes[0])).collect();
        assert_eq!(team, (0..14).collect::<Vec<u8>>());
        assert_eq!(external, (100..114).collect::<Vec<u8>>());
        assert_eq!(
            sent,
            vec![
                LinkOutbox { team: Some(vec![1]), external: Some(vec![2]) },
                LinkOutbox { team: Some(vec![3]), external: None },
            ]
        );
    }

    #[test]
    fn a_robot_without_its_team_link_neither_hears_nor_tells_teammates_through_a_serving_module() {
        let (inboxes, sent) = served_links(false);
        assert_eq!(inboxes.len(), 5);
        assert!(inboxes.iter().all(|inbox| inbox.team.is_empty()));
        assert_eq!(inboxes.iter().map(|inbox| inbox.external.len()).sum::<usize>(), 14);
        // The team message is dropped; an outbox with nothing else is not passed on at all.
        assert_eq!(sent, vec![LinkOutbox { team: None, external: Some(vec![2]) }]);
    }
}
