//! The robots' side of the world: what `SimPlatform`, the links and the network server call.

use strata_robot::Odometry;
use strata_robot::platform::{
    ActuatorOrders, BodyMotionState, LinkError, MotionFeedback, PlatformError, ReceivedPacket,
    SensorFrame,
};
use strata_spl::gamecontroller::ReturnData;

use super::{SimError, Simulation};
use crate::truth::{CommsStats, EventKind, RobotId};

impl Simulation {
    // ---------------------------------------------------------------------------------------
    // The platform's side: what SimPlatform and the network server call.

    /// The newest sensor frame since the last call, with the newest camera image since the
    /// last call attached.
    pub fn take_sensor_frame(&mut self, robot: RobotId) -> Result<Option<SensorFrame>, SimError> {
        let slot = self.slot(robot)?;
        let outbox = &mut self.robots[slot].outbox;
        let Some(mut frame) = outbox.sensors.take() else { return Ok(None) };
        frame.camera = outbox.camera.take();
        Ok(Some(frame))
    }

    /// Gives back a read frame's detections so the next image can reuse the allocation.
    pub fn recycle(&mut self, robot: RobotId, frame: SensorFrame) {
        if let (Ok(slot), Some(camera)) = (self.slot(robot), frame.camera) {
            self.robots[slot].outbox.spare_detections = camera.detections;
        }
    }

    /// The motion state, and the odometry accumulated since the last call.
    pub fn read_motion(&mut self, robot: RobotId) -> Result<MotionFeedback, SimError> {
        let slot = self.slot(robot)?;
        let now = self.time;
        let r = &mut self.robots[slot];
        if !r.present {
            return Ok(MotionFeedback {
                stamp: now,
                body: BodyMotionState::Limp,
                head: r.encoders,
                head_settled: true,
                odometry: Odometry::ZERO,
            });
        }
        let odometry = r.body.take_odometry();
        Ok(MotionFeedback {
            stamp: now,
            body: r.body.motion_state(),
            head: r.encoders,
            head_settled: r.body.head_settled(),
            odometry,
        })
    }

    /// Applies actuator orders now (they take effect from the next step).
    pub fn apply_orders(
        &mut self,
        robot: RobotId,
        orders: &ActuatorOrders,
    ) -> Result<(), PlatformError> {
        let slot = self.slot(robot).map_err(|e| PlatformError::Unsupported(e.to_string()))?;
        let config = &self.config.robot;
        let r = &mut self.robots[slot];
        if !r.present {
            return Ok(());
        }
        if let Some(head) = &orders.head {
            if !(head.target.yaw.is_finite() && head.target.pitch.is_finite()) {
                return Err(PlatformError::Unsupported(format!(
                    "non-finite head target {:?}",
                    head.target
                )));
            }
            r.body.order_head(head, config);
        }
        if let Some(body) = orders.body {
            if let strata_robot::platform::BodyOrder::Walk { velocity } = body
                && !velocity.is_finite()
            {
                return Err(PlatformError::Unsupported(format!(
                    "non-finite walk velocity {velocity:?}"
                )));
            }
            r.body.order_body(body, config).map_err(PlatformError::Unsupported)?;
        }
        Ok(())
    }

    /// A robot's team message: rejected (and counted) above the size limit, accounted in the
    /// team's budget, and forwarded to each teammate with loss, delay and jitter.
    pub fn send_team_message(&mut self, robot: RobotId, bytes: &[u8]) -> Result<(), LinkError> {
        let slot = self.slot(robot).map_err(|e| LinkError::Closed(e.to_string()))?;
        if !self.robots[slot].present {
            return Err(LinkError::Closed(format!("{robot} is not in the game")));
        }
        let team = robot.team;
        let limit = self.config.broadcast.max_message_size;
        if bytes.len() > limit {
            self.comms.rejected_oversize += 1;
            self.count_message(team, false);
            return Err(LinkError::TooLarge { size: bytes.len(), limit });
        }
        if !self.count_message(team, true) {
            self.comms.over_budget += 1;
            if self.config.broadcast.enforce_budget {
                return Ok(());
            }
        }
        self.comms.sent += 1;
        let recipients: Vec<usize> = self
            .robots
            .iter()
            .enumerate()
            .filter(|(s, r)| *s != slot && r.present && r.id.team == team)
            .map(|(s, _)| s)
            .collect();
        let (_, lost) = self.broadcast.send(
            self.time,
            bytes,
            recipients.into_iter(),
            &self.config.broadcast,
            self.broadcast_loss,
            &mut self.comms_rng,
        );
        self.comms.lost += lost;
        Ok(())
    }

    pub(super) fn count_message(&mut self, team: usize, legal: bool) -> bool {
        let was_illegal = self.referee.illegal_communication[team];
        let ok = self.referee.count_message(team, legal);
        if !was_illegal && self.referee.illegal_communication[team] {
            self.event(EventKind::IllegalCommunication { team });
        }
        ok
    }

    /// Team messages delivered to `robot` since the last call, in delivery order.
    pub fn take_team_messages(&mut self, robot: RobotId) -> Result<Vec<ReceivedPacket>, SimError> {
        let slot = self.slot(robot)?;
        Ok(std::mem::take(&mut self.robots[slot].outbox.team))
    }

    /// Control packets (`RGme` bytes) delivered to `robot` since the last call.
    pub fn take_control_packets(
        &mut self,
        robot: RobotId,
    ) -> Result<Vec<ReceivedPacket>, SimError> {
        let slot = self.slot(robot)?;
        Ok(std::mem::take(&mut self.robots[slot].outbox.control))
    }

    /// A return packet (`RGrt`) from a robot. Invalid packets are counted and dropped, as the
    /// GameController drops them.
    pub fn receive_return_packet(&mut self, robot: RobotId, bytes: &[u8]) -> Result<(), SimError> {
        let slot = self.slot(robot)?;
        match ReturnData::decode(bytes) {
            Ok(data) => {
                self.comms.return_packets += 1;
                self.robots[slot].last_return = Some(data);
            }
            Err(error) => {
                self.comms.return_packets_rejected += 1;
                tracing::debug!(%robot, %error, "return packet dropped");
            }
        }
        Ok(())
    }

    /// The last valid return packet of a robot.
    pub fn last_return_packet(&self, robot: RobotId) -> Option<ReturnData> {
        self.slot(robot).ok().and_then(|s| self.robots[s].last_return)
    }

    pub fn comms_stats(&self) -> &CommsStats {
        &self.comms
    }

    /// Team messages still on their way.
    pub fn messages_in_flight(&self) -> usize {
        self.broadcast.in_flight()
    }
}
