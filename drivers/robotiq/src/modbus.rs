//! The Modbus RTU part, through tokio-modbus over a serial port (tokio-serial): identity, a register read
//! of the wrench, the write to register 410 that starts the stream. Every exchange is bounded by a
//! timeout. The blocking entry points run a small single-threaded runtime of their own.

use core::fmt;
use core::time::Duration;
use std::io::Write;
use std::path::Path;

use hal::ErrorKind;
use tokio_modbus::client::{Context, Reader, Writer};
use tokio_modbus::{ExceptionCode, Slave};
use tokio_serial::SerialPortBuilderExt;

use crate::codec::{
    BAUD, Counts, Identity, REG_FIRMWARE, REG_SERIAL, REG_STREAM, REG_WRENCH, REG_YEAR,
    RegisterError, STOP_BYTE, STOP_COUNT, STREAM_START,
};

/// A failed Modbus exchange.
#[derive(Debug)]
#[non_exhaustive]
pub enum ModbusError {
    /// The port could not be opened or used.
    Io(std::io::Error),
    /// No answer in time.
    Timeout {
        /// The exchange.
        what: &'static str,
        /// The limit.
        after: Duration,
    },
    /// The sensor answered with an exception.
    Exception {
        /// The exchange.
        what: &'static str,
        /// The exception.
        code: ExceptionCode,
    },
    /// The reply was malformed (wrong CRC, wrong function, wrong length).
    Protocol {
        /// The exchange.
        what: &'static str,
        /// tokio-modbus's description.
        detail: String,
    },
    /// The registers did not have the expected shape.
    Register(RegisterError),
}

impl fmt::Display for ModbusError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Io(e) => write!(f, "serial port: {e}"),
            Self::Timeout { what, after } => write!(
                f,
                "{what}: no answer within {} ms (is the sensor powered, on this port, at slave 9 and 19200 8N1?)",
                after.as_millis()
            ),
            Self::Exception { what, code } => write!(f, "{what}: exception {code}"),
            Self::Protocol { what, detail } => write!(f, "{what}: {detail}"),
            Self::Register(e) => write!(f, "registers: {e}"),
        }
    }
}

impl std::error::Error for ModbusError {}

impl ModbusError {
    /// The HAL kind.
    pub fn kind(&self) -> ErrorKind {
        match self {
            Self::Io(_) => ErrorKind::Io,
            Self::Timeout { .. } => ErrorKind::Timeout,
            Self::Exception { .. } => ErrorKind::DeviceFault,
            Self::Protocol { .. } | Self::Register(_) => ErrorKind::Malformed,
        }
    }
}

/// What the start-up learned.
#[derive(Clone, Debug, PartialEq)]
pub struct Startup {
    /// Registers 500..=514, or `None` when the sensor was found already streaming (no Modbus exchange).
    pub identity: Option<Identity>,
    /// Registers 180..=185 read before the stream was started.
    pub wrench: Option<Counts>,
}

/// A Modbus session with the sensor.
pub struct Session {
    ctx: Context,
    timeout: Duration,
}

async fn bounded<T>(
    what: &'static str,
    timeout: Duration,
    fut: impl Future<Output = tokio_modbus::Result<T>>,
) -> Result<T, ModbusError> {
    match tokio::time::timeout(timeout, fut).await {
        Err(_) => Err(ModbusError::Timeout {
            what,
            after: timeout,
        }),
        Ok(Err(tokio_modbus::Error::Transport(e))) => Err(ModbusError::Io(e)),
        Ok(Err(e)) => Err(ModbusError::Protocol {
            what,
            detail: e.to_string(),
        }),
        Ok(Ok(Err(code))) => Err(ModbusError::Exception { what, code }),
        Ok(Ok(Ok(v))) => Ok(v),
    }
}

impl Session {
    /// Open `path` (19200 8N1) and talk to `slave`. Must run inside a tokio runtime with I/O enabled.
    pub fn open(path: &Path, slave: u8, timeout: Duration) -> Result<Self, ModbusError> {
        let port = tokio_serial::new(path.to_string_lossy(), BAUD)
            .open_native_async()
            .map_err(|e| ModbusError::Io(e.into()))?;
        Ok(Self {
            ctx: tokio_modbus::client::rtu::attach_slave(port, Slave(slave)),
            timeout,
        })
    }

    async fn read(
        &mut self,
        what: &'static str,
        addr: u16,
        n: u16,
    ) -> Result<Vec<u16>, ModbusError> {
        bounded(what, self.timeout, self.ctx.read_holding_registers(addr, n)).await
    }

    /// Registers 500..=502, 510..=513 and 514.
    pub async fn identity(&mut self) -> Result<Identity, ModbusError> {
        let fw = self.read("firmware (500..502)", REG_FIRMWARE, 3).await?;
        let sn = self.read("serial number (510..513)", REG_SERIAL, 4).await?;
        let year = self.read("production year (514)", REG_YEAR, 1).await?;
        Identity::from_registers(&fw, &sn, &year).map_err(ModbusError::Register)
    }

    /// Registers 180..=185.
    pub async fn wrench(&mut self) -> Result<Counts, ModbusError> {
        let regs = self.read("wrench (180..185)", REG_WRENCH, 6).await?;
        Counts::from_registers(&regs).map_err(ModbusError::Register)
    }

    /// Write 0x0200 to register 410 (function 0x10): the sensor starts streaming after its answer.
    pub async fn start_stream(&mut self) -> Result<(), ModbusError> {
        bounded(
            "start stream (write 410)",
            self.timeout,
            self.ctx
                .write_multiple_registers(REG_STREAM, &[STREAM_START]),
        )
        .await
    }
}

fn runtime() -> Result<tokio::runtime::Runtime, ModbusError> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(ModbusError::Io)
}

/// Blocking: identity and a register read of the wrench; with `start`, then the write that starts the
/// stream. The port is closed when this returns.
pub fn startup(
    path: &Path,
    slave: u8,
    timeout: Duration,
    start: bool,
) -> Result<(Identity, Counts), ModbusError> {
    runtime()?.block_on(async {
        let mut s = Session::open(path, slave, timeout)?;
        let id = s.identity().await?;
        let w = s.wrench().await?;
        if start {
            s.start_stream().await?;
        }
        Ok((id, w))
    })
}

/// Send the stop bytes (0xFF × [`STOP_COUNT`]) on an open port.
pub fn send_stop(port: &mut impl Write) -> std::io::Result<()> {
    port.write_all(&[STOP_BYTE; STOP_COUNT])?;
    port.flush()
}
