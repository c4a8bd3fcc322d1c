//! M62–M68 end to end: kerfd runs a program on the simulated mill with its
//! pins exported over shared memory, and a subscriber reads the outputs.

mod support;

use std::time::{Duration, Instant};

use kerf::protocol::{Command, ProgramState};
use kerf_io::shm::Services;
use support::Kerfd;

/// The last value kerf published on pin `pin` of `instance`.
fn last_value(services: &Services, instance: &str, pin: &str) -> f64 {
    let subscriber = services.pin_subscriber(instance, pin).unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut last = None;
    while Instant::now() < deadline {
        while let Some(s) = subscriber.receive().unwrap() {
            last = Some(s.value);
        }
        if let Some(v) = last {
            return v;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    panic!("no value on pin {pin}");
}

#[test]
fn kerfd_sets_the_pins_a_program_asks_for() {
    let instance = format!("kerf-pins-e2e-{}", std::process::id());
    let dir = std::sync::Arc::new(tempfile::tempdir().unwrap());
    let mill = include_str!("../machines/mill3.toml");
    let machine = dir.path().join("mill-pins.toml");
    std::fs::write(
        &machine,
        format!("{mill}\n[hal.shm]\ninstance = \"{instance}\"\n"),
    )
    .unwrap();
    let kerfd = Kerfd::start_in(dir, &["--machine", machine.to_str().unwrap()], &[]);
    let mut client = kerfd.ready_client();
    let program = kerfd.program(
        "pins.ngc",
        "G21 G90 G1 X10 F3000\nM62 P2\nM67 E1 Q3.5\nG1 X20\nM64 P0\nM68 E0 Q-2\nM65 P0\nM64 P3\nM2\n",
    );
    let id = support::start_program(&mut client, &program);
    let end = client.wait_job(id, 50.0, |_| {}).unwrap();
    let p = end.program.as_ref().unwrap();
    assert_eq!(p.state, ProgramState::Finished, "{:?}", p.error);

    let services = Services::new().unwrap();
    let pin = |name: &str| last_value(&services, &instance, name);
    assert_eq!(pin("dout-0"), 0.0, "M64 then M65");
    assert_eq!(pin("dout-2"), 1.0, "M62 with the second move");
    assert_eq!(pin("dout-3"), 1.0, "M64");
    assert_eq!(pin("aout-0"), -2.0, "M68");
    assert_eq!(pin("aout-1"), 3.5, "M67 with the second move");

    // A pin the machine does not have is refused before anything moves.
    let bad = kerfd.program("bad.ngc", "G1 X5 F600\nM62 P4\nG1 X6\nM2\n");
    let run = Command::Run {
        path: Some(bad.display().to_string()),
        line: None,
    };
    let e = client.request(&run).unwrap_err().to_string();
    assert!(
        e.contains("bad.ngc:2") && e.contains("no digital output 4"),
        "{e}"
    );
}

#[test]
fn m66_answers_the_program_from_the_machines_input() {
    // Input 0 of the simulated mill stays low: waiting for it to go high
    // times out (#5399 = −1) and the program takes its first branch; read
    // at once (L0) it answers 0 and the program takes the other. The
    // offline check before the run reads inputs as 0 either way, so only
    // a real wait can reach X5.
    let kerfd = Kerfd::start(&["--virtual-clock"]);
    let mut client = kerfd.ready_client();
    for (wait, want) in [("L3 Q0.2", 5.0), ("L0", 7.0)] {
        let program = kerfd.program(
            "wait.ngc",
            &format!(
                "G21 G90\nM66 P0 {wait}\no100 if [#5399 EQ -1]\nG0 X5\no100 else\nG0 X7\no100 endif\nM2\n"
            ),
        );
        let id = support::start_program(&mut client, &program);
        let end = client.wait_job(id, 50.0, |_| {}).unwrap();
        let p = end.program.as_ref().unwrap();
        assert_eq!(p.state, ProgramState::Finished, "{:?}", p.error);
        assert_eq!(support::axis(&end, "x"), want, "M66 {wait}");
    }
}
