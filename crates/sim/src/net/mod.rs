//! The simulator over TCP (paper 4.1): the server runs the world in real time and talks to one
//! process per robot; robot processes use [`client::connect`] and get a platform and links that
//! implement the same traits as the in-process ones. The protocol is versioned and
//! length-prefixed ([`protocol`], `docs/sim-protocol.md`).

pub mod client;
pub mod protocol;
pub mod server;

pub use client::{
    ClientOptions, ConnectError, TcpGameControllerLink, TcpRobot, TcpSimPlatform, TcpTeamLink,
    Welcome, connect, connect_with,
};
pub use protocol::{ClientMessage, DEFAULT_ADDR, ErrorCode, ServerMessage};
pub use server::{
    RunningServer, Server, ServerCounters, ServerError, ServerLimits, ServerOptions, ServerStatus,
};
