//! Status and pins over iceoryx2 shared memory: LinuxCNC's HAL idea
//! (named pins other processes can watch and drive) without a kernel
//! module.
//!
//! Services, for an instance name `I` (the machine's, by default):
//!
//! | service | payload | who publishes |
//! | --- | --- | --- |
//! | `kerf/I/status` | [`StatusFrame`] | kerf, every servo tick |
//! | `kerf/I/pin/NAME` for each output pin | [`PinSample`] | kerf, when the value changes |
//! | `kerf/I/pin/NAME` for each input pin | [`PinSample`] | another process; kerf subscribes |
//!
//! Every service keeps its last sample for late subscribers (history 1).
//! The servo tick never touches iceoryx2: [`ShmExport::exchange`] pushes
//! the tick's status and outputs into a lock-free queue and reads inputs
//! from atomics; a thread of its own publishes and subscribes.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;

use crate::pins::{PinBank, PinConfig, MAX_ANALOG, MAX_DIGITAL};
use crate::MAX_JOINTS;

/// Machine state codes in [`StatusFrame::state`].
pub mod state {
    /// Emergency stop / drives off.
    pub const ESTOP: u32 = 0;
    /// On and idle.
    pub const IDLE: u32 = 1;
    /// Running a program.
    pub const RUNNING: u32 = 2;
    /// Paused.
    pub const PAUSED: u32 = 3;
    /// Stopped by a fault.
    pub const FAULT: u32 = 4;
}

/// The status snapshot published every servo tick. Plain data, the same
/// layout in every process (`repr(C)`).
#[derive(Clone, Copy, Debug, PartialEq, ZeroCopySend)]
#[repr(C)]
pub struct StatusFrame {
    /// Servo tick number.
    pub tick: u64,
    /// Number of joints used in the arrays.
    pub joint_count: u32,
    /// Machine state, one of [`state`].
    pub state: u32,
    /// Joint feedback positions, mm (degrees for rotary joints).
    pub position: [f64; MAX_JOINTS],
    /// Joint feedback velocities, mm/s.
    pub velocity: [f64; MAX_JOINTS],
    /// Commanded minus measured joint position, mm.
    pub following_error: [f64; MAX_JOINTS],
    /// Feed override in force, 1.0 = 100 %.
    pub feed_override: f64,
    /// Cutting force estimate, N (0 where not modelled).
    pub force: f64,
    /// Source line being executed (0: none).
    pub line: u32,
    /// Non-zero while a fault stops motion.
    pub fault: u32,
}

impl Default for StatusFrame {
    fn default() -> Self {
        StatusFrame {
            tick: 0,
            joint_count: 0,
            state: state::ESTOP,
            position: [0.0; MAX_JOINTS],
            velocity: [0.0; MAX_JOINTS],
            following_error: [0.0; MAX_JOINTS],
            feed_override: 1.0,
            force: 0.0,
            line: 0,
            fault: 0,
        }
    }
}

/// One pin's value: digital pins are 0.0 or 1.0.
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
pub struct PinSample {
    /// The value.
    pub value: f64,
    /// Publisher's tick (kerf's servo tick for outputs) when it was set.
    pub tick: u64,
}

/// Name of the status service of instance `instance`.
pub fn status_service(instance: &str) -> String {
    format!("kerf/{instance}/status")
}

/// Name of the service of pin `pin` of instance `instance`.
pub fn pin_service(instance: &str, pin: &str) -> String {
    format!("kerf/{instance}/pin/{pin}")
}

type PortFactory<T> =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, ()>;

/// Errors setting up shared memory.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("shared memory service {service}: {reason}")]
pub struct ShmError {
    /// The service name.
    pub service: String,
    /// What iceoryx2 said.
    pub reason: String,
}

/// The node and the services, with the QoS every kerf process uses (both
/// ends must agree or opening fails).
pub struct Services {
    node: Node<ipc::Service>,
}

impl Services {
    /// A node for this process.
    pub fn new() -> Result<Services, ShmError> {
        let node = NodeBuilder::new()
            .create::<ipc::Service>()
            .map_err(|e| ShmError {
                service: "(node)".into(),
                reason: format!("{e:?}"),
            })?;
        Ok(Services { node })
    }

    fn open<T: std::fmt::Debug + ZeroCopySend + Copy + 'static>(
        &self,
        name: &str,
    ) -> Result<
        iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, ()>,
        ShmError,
    > {
        let err = |reason: String| ShmError {
            service: name.to_string(),
            reason,
        };
        let service_name: ServiceName = name.try_into().map_err(|e| err(format!("{e:?}")))?;
        self.node
            .service_builder(&service_name)
            .publish_subscribe::<T>()
            .history_size(1)
            .subscriber_max_buffer_size(64)
            .max_publishers(4)
            .max_subscribers(16)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(|e| err(format!("{e:?}")))
    }

    /// Open `name` for payload `T` and make a port on it with `make`.
    fn port<T, P, E>(
        &self,
        name: String,
        make: impl FnOnce(&PortFactory<T>) -> Result<P, E>,
    ) -> Result<P, ShmError>
    where
        T: std::fmt::Debug + ZeroCopySend + Copy + 'static,
        E: std::fmt::Debug,
    {
        let factory = self.open::<T>(&name)?;
        make(&factory).map_err(|e| ShmError {
            service: name,
            reason: format!("{e:?}"),
        })
    }

    /// A publisher of status frames.
    pub fn status_publisher(
        &self,
        instance: &str,
    ) -> Result<Publisher<ipc::Service, StatusFrame, ()>, ShmError> {
        self.port(status_service(instance), |f| f.publisher_builder().create())
    }

    /// A subscriber to status frames.
    pub fn status_subscriber(
        &self,
        instance: &str,
    ) -> Result<Subscriber<ipc::Service, StatusFrame, ()>, ShmError> {
        self.port(status_service(instance), |f| {
            f.subscriber_builder().create()
        })
    }

    /// A publisher of a pin's values.
    pub fn pin_publisher(
        &self,
        instance: &str,
        pin: &str,
    ) -> Result<Publisher<ipc::Service, PinSample, ()>, ShmError> {
        self.port(pin_service(instance, pin), |f| {
            f.publisher_builder().create()
        })
    }

    /// A subscriber to a pin's values.
    pub fn pin_subscriber(
        &self,
        instance: &str,
        pin: &str,
    ) -> Result<Subscriber<ipc::Service, PinSample, ()>, ShmError> {
        self.port(pin_service(instance, pin), |f| {
            f.subscriber_builder().create()
        })
    }
}

#[derive(Clone, Copy)]
struct TickMsg {
    status: StatusFrame,
    digital_out: u64,
    analog_out: [f64; MAX_ANALOG],
}

#[derive(Default)]
struct Shared {
    stop: AtomicBool,
    /// Digital inputs as last received, bit n = input n.
    digital_in: AtomicU64,
    /// Analog inputs as last received (f64 bits).
    analog_in: [AtomicU64; MAX_ANALOG],
    /// Status frames published.
    published: AtomicU64,
    /// Ticks dropped because the export thread fell behind.
    dropped: AtomicU64,
    /// The first error the export thread met (it then stops).
    failed: AtomicBool,
}

/// The servo side of the shared-memory export.
pub struct ShmExport {
    queue: rtrb::Producer<TickMsg>,
    shared: Arc<Shared>,
    wake: std::thread::Thread,
    thread: Option<JoinHandle<()>>,
    dropped: u64,
}

/// Ticks the export thread may fall behind before frames are dropped.
const QUEUE: usize = 256;

impl ShmExport {
    /// Create the services of `instance` for `pins` and start the export
    /// thread. Fails if a service cannot be created (e.g. another process
    /// opened it with other settings).
    pub fn start(instance: &str, pins: &PinConfig) -> Result<ShmExport, ShmError> {
        pins.validate().map_err(|e| ShmError {
            service: pin_service(instance, "*"),
            reason: e.to_string(),
        })?;
        let (producer, consumer) = rtrb::RingBuffer::new(QUEUE);
        let shared = Arc::new(Shared::default());
        let (ready_tx, ready_rx) = std::sync::mpsc::channel();
        let (instance, pins, thread_shared) = (instance.to_string(), pins.clone(), shared.clone());
        // iceoryx2 ports stay on the thread that made them.
        let thread = std::thread::Builder::new()
            .name("kerf-shm".into())
            .spawn(move || match Exporter::new(&instance, &pins) {
                Ok(ex) => {
                    let _ = ready_tx.send(Ok(()));
                    ex.run(consumer, &thread_shared);
                }
                Err(e) => {
                    let _ = ready_tx.send(Err(e));
                }
            })
            .map_err(|e| ShmError {
                service: "(thread)".into(),
                reason: e.to_string(),
            })?;
        ready_rx.recv().map_err(|_| ShmError {
            service: "(thread)".into(),
            reason: "the export thread died while starting".into(),
        })??;
        Ok(ShmExport {
            queue: producer,
            shared,
            wake: thread.thread().clone(),
            thread: Some(thread),
            dropped: 0,
        })
    }

    /// Once per servo tick: queue `status` and `pins`' outputs for
    /// publishing, and copy the latest input values into `pins`. Real-time
    /// safe: no allocation, lock or blocking. A tick that finds the queue
    /// full is dropped (and counted): status export never stalls motion.
    pub fn exchange(&mut self, status: &StatusFrame, pins: &mut PinBank) {
        let mut analog_out = [0.0; MAX_ANALOG];
        for (n, a) in analog_out.iter_mut().enumerate() {
            *a = pins.analog_out(n);
        }
        let msg = TickMsg {
            status: *status,
            digital_out: pins.digital_outputs(),
            analog_out,
        };
        if self.queue.push(msg).is_err() {
            self.dropped += 1;
            self.shared.dropped.store(self.dropped, Ordering::Relaxed);
        }
        self.wake.unpark();
        let digital = self.shared.digital_in.load(Ordering::Acquire);
        let (_, din, _, ain) = pins.counts();
        for n in 0..din.min(MAX_DIGITAL) {
            pins.store_digital_in(n, digital >> n & 1 == 1);
        }
        for n in 0..ain {
            pins.store_analog_in(
                n,
                f64::from_bits(self.shared.analog_in[n].load(Ordering::Acquire)),
            );
        }
    }

    /// Status frames published so far.
    pub fn published(&self) -> u64 {
        self.shared.published.load(Ordering::Acquire)
    }

    /// Ticks dropped because the export thread fell behind.
    pub fn dropped(&self) -> u64 {
        self.shared.dropped.load(Ordering::Relaxed)
    }

    /// Whether the export thread stopped on an error.
    pub fn failed(&self) -> bool {
        self.shared.failed.load(Ordering::Relaxed)
    }
}

impl Drop for ShmExport {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        self.wake.unpark();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The export thread's ports.
struct Exporter {
    _services: Services,
    status: Publisher<ipc::Service, StatusFrame, ()>,
    digital_out: Vec<Publisher<ipc::Service, PinSample, ()>>,
    analog_out: Vec<Publisher<ipc::Service, PinSample, ()>>,
    digital_in: Vec<Subscriber<ipc::Service, PinSample, ()>>,
    analog_in: Vec<Subscriber<ipc::Service, PinSample, ()>>,
}

impl Exporter {
    fn new(instance: &str, pins: &PinConfig) -> Result<Exporter, ShmError> {
        let s = Services::new()?;
        let pubs = |names: &[String]| -> Result<Vec<_>, ShmError> {
            names.iter().map(|n| s.pin_publisher(instance, n)).collect()
        };
        let subs = |names: &[String]| -> Result<Vec<_>, ShmError> {
            names
                .iter()
                .map(|n| s.pin_subscriber(instance, n))
                .collect()
        };
        Ok(Exporter {
            status: s.status_publisher(instance)?,
            digital_out: pubs(&pins.digital_out)?,
            analog_out: pubs(&pins.analog_out)?,
            digital_in: subs(&pins.digital_in)?,
            analog_in: subs(&pins.analog_in)?,
            _services: s,
        })
    }

    fn run(self, mut queue: rtrb::Consumer<TickMsg>, shared: &Shared) {
        let mut last: Option<TickMsg> = None;
        while !shared.stop.load(Ordering::Relaxed) {
            let mut any = false;
            while let Ok(msg) = queue.pop() {
                any = true;
                if self.publish(&msg, last.as_ref()).is_err() {
                    shared.failed.store(true, Ordering::Relaxed);
                    return;
                }
                shared.published.fetch_add(1, Ordering::Release);
                last = Some(msg);
            }
            if self.read_inputs(shared).is_err() {
                shared.failed.store(true, Ordering::Relaxed);
                return;
            }
            if !any {
                // Woken by the next tick; the timeout keeps inputs fresh
                // while the servo is not ticking.
                std::thread::park_timeout(Duration::from_millis(2));
            }
        }
    }

    fn publish(&self, msg: &TickMsg, last: Option<&TickMsg>) -> Result<(), ()> {
        self.status.send_copy(msg.status).map_err(|_| ())?;
        let tick = msg.status.tick;
        for (n, p) in self.digital_out.iter().enumerate() {
            let v = msg.digital_out >> n & 1;
            if last.is_none_or(|l| l.digital_out >> n & 1 != v) {
                p.send_copy(PinSample {
                    value: v as f64,
                    tick,
                })
                .map_err(|_| ())?;
            } else {
                // Hands the last value (history) to subscribers that came
                // since: an unchanged pin sends nothing else.
                p.update_connections().map_err(|_| ())?;
            }
        }
        for (n, p) in self.analog_out.iter().enumerate() {
            let v = msg.analog_out[n];
            if last.is_none_or(|l| l.analog_out[n].to_bits() != v.to_bits()) {
                p.send_copy(PinSample { value: v, tick }).map_err(|_| ())?;
            } else {
                p.update_connections().map_err(|_| ())?;
            }
        }
        Ok(())
    }

    fn read_inputs(&self, shared: &Shared) -> Result<(), ()> {
        let mut bits = shared.digital_in.load(Ordering::Relaxed);
        for (n, s) in self.digital_in.iter().enumerate() {
            while let Some(sample) = s.receive().map_err(|_| ())? {
                let on = sample.value != 0.0;
                bits = (bits & !(1 << n)) | ((on as u64) << n);
            }
        }
        shared.digital_in.store(bits, Ordering::Release);
        for (n, s) in self.analog_in.iter().enumerate() {
            while let Some(sample) = s.receive().map_err(|_| ())? {
                shared.analog_in[n].store(sample.value.to_bits(), Ordering::Release);
            }
        }
        Ok(())
    }
}
