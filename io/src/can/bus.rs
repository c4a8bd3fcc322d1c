//! The CAN bus as the CiA 402 master sees it, and its SocketCAN
//! implementation.

use std::time::Duration;

/// A classic CAN data frame with an 11-bit identifier (CANopen uses only
/// these).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Frame {
    /// COB-ID, 0 to 0x7FF.
    pub id: u16,
    /// Data length, 0 to 8.
    pub len: u8,
    /// Data bytes (the first `len` are used).
    pub data: [u8; 8],
}

impl Frame {
    /// A frame with `data` (at most 8 bytes).
    pub fn new(id: u16, data: &[u8]) -> Frame {
        let mut f = Frame {
            id,
            len: data.len() as u8,
            data: [0; 8],
        };
        f.data[..data.len()].copy_from_slice(data);
        f
    }

    /// The used data bytes.
    pub fn bytes(&self) -> &[u8] {
        &self.data[..self.len as usize]
    }
}

/// Why the bus failed.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum BusError {
    /// The interface is gone or refuses frames (bus off, link down).
    #[error("CAN interface error: {0}")]
    Io(String),
}

/// A CAN bus: send frames, receive the frames other nodes send.
pub trait Bus: Send {
    /// Queue a frame for sending. Does not wait for the bus.
    fn send(&mut self, frame: &Frame) -> Result<(), BusError>;

    /// The next received frame, if one is waiting; does not wait.
    fn try_recv(&mut self) -> Result<Option<Frame>, BusError>;

    /// The next received frame, waiting up to `timeout` (start-up only).
    fn recv_timeout(&mut self, timeout: Duration) -> Result<Option<Frame>, BusError>;
}

/// A SocketCAN interface (`can0`, `vcan0`) through the socketcan crate.
///
/// Frames with extended identifiers, remote frames and error frames are
/// ignored: CANopen uses none of them.
pub struct SocketCan {
    socket: socketcan::CanSocket,
}

impl SocketCan {
    /// Open interface `name` (it must be up: `ip link set can0 up type can
    /// bitrate 1000000`).
    pub fn open(name: &str) -> Result<SocketCan, BusError> {
        use socketcan::Socket;
        let socket = socketcan::CanSocket::open(name)
            .map_err(|e| BusError::Io(format!("cannot open CAN interface {name}: {e}")))?;
        socket
            .set_nonblocking(true)
            .map_err(|e| BusError::Io(format!("{name}: {e}")))?;
        Ok(SocketCan { socket })
    }

    fn convert(frame: socketcan::CanFrame) -> Option<Frame> {
        use socketcan::{EmbeddedFrame, Frame as _};
        match frame {
            socketcan::CanFrame::Data(d) if !d.is_extended() => {
                Some(Frame::new(d.raw_id() as u16, d.data()))
            }
            _ => None,
        }
    }
}

impl Bus for SocketCan {
    fn send(&mut self, frame: &Frame) -> Result<(), BusError> {
        use socketcan::{EmbeddedFrame, Socket, StandardId};
        let id = StandardId::new(frame.id)
            .ok_or_else(|| BusError::Io(format!("COB-ID {:#x} is not 11-bit", frame.id)))?;
        let f = socketcan::CanFrame::new(id, frame.bytes())
            .ok_or_else(|| BusError::Io("frame longer than 8 bytes".into()))?;
        self.socket
            .write_frame(&f)
            .map_err(|e| BusError::Io(format!("send: {e}")))
    }

    fn try_recv(&mut self) -> Result<Option<Frame>, BusError> {
        use socketcan::Socket;
        loop {
            match self.socket.read_frame() {
                Ok(f) => {
                    if let Some(f) = SocketCan::convert(f) {
                        return Ok(Some(f));
                    }
                }
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => return Ok(None),
                Err(e) => return Err(BusError::Io(format!("receive: {e}"))),
            }
        }
    }

    fn recv_timeout(&mut self, timeout: Duration) -> Result<Option<Frame>, BusError> {
        use socketcan::Socket;
        let deadline = std::time::Instant::now() + timeout;
        loop {
            if let Some(f) = self.try_recv()? {
                return Ok(Some(f));
            }
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            if left.is_zero() {
                return Ok(None);
            }
            // Blocking read with the remaining time, then back to
            // non-blocking for the cyclic path.
            self.socket
                .set_nonblocking(false)
                .map_err(|e| BusError::Io(e.to_string()))?;
            let r = self.socket.read_frame_timeout(left);
            self.socket
                .set_nonblocking(true)
                .map_err(|e| BusError::Io(e.to_string()))?;
            match r {
                Ok(f) => {
                    if let Some(f) = SocketCan::convert(f) {
                        return Ok(Some(f));
                    }
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) =>
                {
                    return Ok(None)
                }
                Err(e) => return Err(BusError::Io(format!("receive: {e}"))),
            }
        }
    }
}
