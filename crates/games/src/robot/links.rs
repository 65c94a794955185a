//! The robot's team and GameController links: UDP on a field, or the ones the platform
//! carries; and the attack direction the first control packet tells.

use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result, bail};
use strata_robot::platform::{ExternalLink, ReceivedPacket, TeamLink};
use strata_runtime::{Clock, MonotonicClock};
use strata_spl::gamecontroller::GameControlData;

use super::platform::PlatformLinks;
use super::report::Endpoints;
use super::{PlatformKind, RobotOptions};
use crate::links::{self, Counted, LinkCounters, NetConfig, Prefetched};

/// A robot's links and what the start line and the report say of them.
pub(crate) struct OpenLinks {
    pub(crate) team: Option<Box<dyn TeamLink>>,
    pub(crate) game_controller: Box<dyn ExternalLink>,
    pub(crate) team_counters: Arc<LinkCounters>,
    pub(crate) gc_counters: Arc<LinkCounters>,
    pub(crate) endpoints: Endpoints,
    /// Links the platform carries that the robot does not use: drained now and then so they
    /// do not pile up.
    pub(crate) unused: Vec<Box<dyn FnMut() + Send>>,
}

/// The team and GameController links: UDP on a field (`--net`, always on a NAO), or the ones
/// the platform carries (with `--team-udp`, the team's over UDP).
pub(crate) fn open_links(
    opts: &RobotOptions,
    platform_links: Option<PlatformLinks>,
    early_clock: MonotonicClock,
) -> Result<OpenLinks> {
    let net = opts.net || opts.platform == PlatformKind::Nao;
    let mut unused_sim_links: Vec<Box<dyn FnMut() + Send>> = Vec::new();
    let (team, game_controller, team_counters, gc_counters, endpoints) = if net {
        let net_config = net_config(opts)?;
        let (team, gc) = net_config.bind().with_context(|| {
            format!(
                "binding UDP ports {} (GameController) and {} (team)",
                net_config.gc_port, net_config.team_port
            )
        })?;
        let endpoints = Endpoints {
            game_controller: format!(
                "UDP :{} (return packets to the sender's :{})",
                net_config.gc_port, net_config.gc_return_port
            ),
            team: format!(
                "UDP :{} -> {}:{}",
                net_config.team_port, net_config.broadcast, net_config.team_port
            ),
        };
        let (team_counters, gc_counters) = (team.counters(), gc.counters());
        if let Some(links) = platform_links {
            // The server still forwards its referee's packets and teammates' messages; drain
            // them so they do not pile up in the client.
            let PlatformLinks { mut team_link, mut game_controller, .. } = links;
            let clock = early_clock;
            unused_sim_links.push(Box::new(move || {
                if let Some(team_link) = &mut team_link {
                    let _ = team_link.receive(clock.now());
                }
                let _ = game_controller.receive(clock.now());
            }));
        }
        let team: Box<dyn TeamLink> = Box::new(team);
        let gc: Box<dyn ExternalLink> = Box::new(gc);
        (Some(team), gc, team_counters, gc_counters, endpoints)
    } else {
        let Some(PlatformLinks { team_link, game_controller, label }) = platform_links else {
            bail!("without --net the simulator server must carry team messages and game state");
        };
        let gc_counters = Arc::<LinkCounters>::default();
        let (team, team_counters, team_label): (Option<Box<dyn TeamLink>>, _, _) = if opts.team_udp
        {
            let net_config = net_config(opts)?;
            let udp = links::UdpTeamLink::bind(net_config.team_port, net_config.broadcast)
                .with_context(|| format!("binding UDP port {} (team)", net_config.team_port))?;
            let counters = udp.counters();
            let label = format!(
                "UDP :{} -> {}:{}",
                net_config.team_port, net_config.broadcast, net_config.team_port
            );
            (Some(Box::new(udp)), counters, label)
        } else {
            let counters = Arc::<LinkCounters>::default();
            let link = team_link.map(|link| {
                Box::new(Counted::new(link, Arc::clone(&counters))) as Box<dyn TeamLink>
            });
            let label = match link {
                Some(_) => label.to_owned(),
                None => "none (the platform carries no team messages; --team-udp or --net \
                             for UDP)"
                    .to_owned(),
            };
            (link, counters, label)
        };
        let gc: Box<dyn ExternalLink> =
            Box::new(Counted::new(game_controller, Arc::clone(&gc_counters)));
        let endpoints = Endpoints { game_controller: label.to_owned(), team: team_label };
        (team, gc, team_counters, gc_counters, endpoints)
    };
    Ok(OpenLinks {
        team,
        game_controller,
        team_counters,
        gc_counters,
        endpoints,
        unused: unused_sim_links,
    })
}

pub(crate) fn net_config(opts: &RobotOptions) -> Result<NetConfig> {
    let mut config = NetConfig::field(opts.team);
    if let Some(interface) = &opts.interface {
        config.broadcast = links::directed_broadcast(interface).map_err(anyhow::Error::msg)?;
    }
    if let Some(broadcast) = opts.broadcast {
        config.broadcast = broadcast;
    }
    if let Some(port) = opts.gc_port {
        config.gc_port = port;
    }
    if let Some(port) = opts.gc_return_port {
        config.gc_return_port = port;
    }
    if let Some(port) = opts.team_port {
        config.team_port = port;
    }
    Ok(config)
}

/// Reads the GameController link for up to `wait` seconds for a control packet of this team;
/// every packet read is handed to the robot afterwards.
pub(crate) fn learn_attack_sign(
    mut link: Box<dyn ExternalLink>,
    team: u8,
    given: Option<f64>,
    wait: f64,
    clock: &MonotonicClock,
) -> (Box<dyn ExternalLink>, f64, String) {
    if let Some(sign) = given {
        return (link, sign, "--attack-sign".to_owned());
    }
    let deadline = Instant::now() + Duration::from_secs_f64(wait);
    let mut read: Vec<ReceivedPacket> = Vec::new();
    let mut found = None;
    loop {
        if let Ok(packets) = link.receive(clock.now()) {
            found = packets.iter().filter_map(|p| GameControlData::decode(&p.bytes).ok()).find_map(
                |data| links::attack_sign(&data, team).map(|sign| (sign, data.first_half)),
            );
            read.extend(packets);
        }
        if found.is_some() || Instant::now() >= deadline {
            break;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let link: Box<dyn ExternalLink> =
        if read.is_empty() { link } else { Box::new(Prefetched::new(read, link)) };
    match found {
        Some((sign, first_half)) => (
            link,
            sign,
            format!("GameController ({} half)", if first_half { "first" } else { "second" }),
        ),
        None => (link, 1.0, "default: no GameController packet for this team yet".to_owned()),
    }
}
