//! The monitor (trainer) port: commands that move the ball and robots and start play, and the
//! state stream the server sends back, for test harnesses.

mod command;
mod state;

use std::net::{SocketAddr, TcpStream, ToSocketAddrs};
use std::time::Duration;

pub use command::{MonitorCommand, RobotOrientation, TeamRef, encode_monitor_commands};
pub use state::{MonitorDecoder, MonitorGame, MonitorState, RobotTruth};

use super::ProtocolError;
use super::frame::{MAX_MONITOR_FRAME, read_frame, write_frame};

/// A blocking connection to the server's monitor port.
///
/// The server streams a state message to every monitor each second cycle and writes it from
/// its simulation thread: a monitor that stops reading fills the socket buffers and then stalls
/// the whole simulation. Call [`MonitorClient::next_state`] regularly (or drop the client).
#[derive(Debug)]
pub struct MonitorClient {
    stream: TcpStream,
    buffer: Vec<u8>,
    outgoing: Vec<u8>,
    decoder: MonitorDecoder,
}

impl MonitorClient {
    /// Connects to the monitor port at `address`, giving up after `timeout` per address tried.
    /// Reads then time out after `timeout` too ([`MonitorClient::set_read_timeout`] changes it).
    pub fn connect(address: impl ToSocketAddrs, timeout: Duration) -> Result<Self, ProtocolError> {
        let addresses: Vec<SocketAddr> = address
            .to_socket_addrs()
            .map_err(|source| ProtocolError::Connect {
                address: "(unresolved)".to_owned(),
                source,
            })?
            .collect();
        let mut last = None;
        for candidate in addresses {
            match TcpStream::connect_timeout(&candidate, timeout) {
                Ok(stream) => {
                    let setup = stream
                        .set_nodelay(true)
                        .and_then(|()| stream.set_read_timeout(Some(timeout)))
                        .and_then(|()| stream.set_write_timeout(Some(timeout)));
                    if let Err(source) = setup {
                        return Err(ProtocolError::Connect {
                            address: candidate.to_string(),
                            source,
                        });
                    }
                    return Ok(Self {
                        stream,
                        buffer: Vec::new(),
                        outgoing: Vec::new(),
                        decoder: MonitorDecoder::new(),
                    });
                }
                Err(source) => last = Some((candidate, source)),
            }
        }
        Err(match last {
            Some((candidate, source)) => {
                ProtocolError::Connect { address: candidate.to_string(), source }
            }
            None => ProtocolError::Connect {
                address: "(no address)".to_owned(),
                source: std::io::Error::new(
                    std::io::ErrorKind::NotFound,
                    "the address resolved to nothing",
                ),
            },
        })
    }

    /// Changes how long [`MonitorClient::next_state`] waits (`None`: forever).
    pub fn set_read_timeout(&mut self, timeout: Option<Duration>) -> Result<(), ProtocolError> {
        self.stream.set_read_timeout(timeout).map_err(|e| ProtocolError::Frame(e.into()))
    }

    /// Sends `commands` as one message. The server applies them after its next physics step.
    pub fn send(&mut self, commands: &[MonitorCommand]) -> Result<(), ProtocolError> {
        encode_monitor_commands(commands, &mut self.outgoing)?;
        write_frame(&mut self.stream, &self.outgoing)?;
        Ok(())
    }

    /// Reads and decodes the next state message.
    pub fn next_state(&mut self) -> Result<&MonitorState, ProtocolError> {
        let payload = read_frame(&mut self.stream, &mut self.buffer, MAX_MONITOR_FRAME)?;
        self.decoder.decode(payload)
    }

    /// The state as of the last message read.
    pub fn state(&self) -> &MonitorState {
        self.decoder.state()
    }
}
