//! M62–M68 through planner and servo tick on the simulated mill, on a
//! virtual clock: each output changes in the period the G-code says, as
//! seen on the commanded position.

use std::sync::Arc;

use kerf::servo::{ServoCommand, ServoTick, Snapshot};
use kerf_interp::{Interpreter, Position};
use kerf_motion::{Planner, PlannerConfig, Segment, SegmentKind};

/// One servo period: what the tool was commanded to and the outputs.
#[derive(Clone, Copy, Debug)]
struct Period {
    commanded: Position,
    velocity: f64,
    digital: u64,
    analog: [f64; 2],
    /// M66 waits answered so far, and the last answer.
    inputs_answered: u64,
    input_value: f64,
}

/// Plan `program` on mill3 (with its `[hal.pins]`), run it to its end and
/// return every period.
fn run(program: &str) -> Vec<Period> {
    run_with_input(program, |_| false)
}

/// As [`run`], with digital input 0 set by `input` in each period (by
/// period number).
fn run_with_input(program: &str, input: impl Fn(usize) -> bool) -> Vec<Period> {
    let machine = kerf_machines::load("mill3").unwrap();
    let kins = machine.kinematics.clone();
    let hal_config: kerf_io::HalConfig = machine.description.hal.clone().try_into().unwrap();
    let hal = kerf_io::build(&hal_config, &[0.0, 0.0, 0.0]).unwrap();
    let (mut producer, consumer) = rtrb::RingBuffer::new(1024);
    let (mut commands, command_queue) = rtrb::RingBuffer::new(16);
    let config = PlannerConfig {
        digital_outputs: hal_config.pins.digital_out.len(),
        analog_outputs: hal_config.pins.analog_out.len(),
        digital_inputs: hal_config.pins.digital_in.len(),
        analog_inputs: hal_config.pins.analog_in.len(),
        ..PlannerConfig::default()
    };
    let mut planner = Planner::new(&*kins, Position::ZERO, config);
    for canon in Interpreter::from_text(program, "pins.ngc", Position::ZERO) {
        planner.plan(&canon.unwrap()).unwrap();
    }
    planner.finish();
    while let Some(seg) = planner.next_segment() {
        producer.push(seg).unwrap();
    }
    let end = planner.position();
    producer
        .push(Segment::marker(SegmentKind::Stop { tag: 1 }, 0, end))
        .unwrap();
    let mut tick = ServoTick::new(
        0.001,
        Position::ZERO,
        Arc::clone(&kins),
        hal,
        consumer,
        command_queue,
    )
    .unwrap();
    tick.set_pins(kerf_io::PinBank::new(&hal_config.pins));
    commands.push(ServoCommand::Enable(true)).unwrap();
    let mut periods = Vec::new();
    for n in 0..100_000 {
        tick.pins_mut().store_digital_in(0, input(n));
        let snap: Snapshot = *tick.tick();
        let pins = tick.pins();
        periods.push(Period {
            commanded: snap.commanded,
            velocity: snap.velocity,
            digital: pins.digital_outputs(),
            analog: [pins.analog_out(0), pins.analog_out(1)],
            inputs_answered: snap.inputs_answered,
            input_value: snap.input_value,
        });
        if snap.program_done == 1 {
            return periods;
        }
    }
    panic!("the program did not finish");
}

fn first(periods: &[Period], what: impl Fn(&Period) -> bool) -> usize {
    periods.iter().position(what).expect("never happened")
}

#[test]
fn m62_turns_on_in_the_period_the_next_move_leaves_its_start() {
    let p = run("G21 G90 G1 X10 F600\nM62 P0\nG1 X20\nM63 P0\nG1 X25\nM2\n");
    let on = first(&p, |q| q.digital & 1 == 1);
    let left = first(&p, |q| q.commanded.x > 10.0);
    assert_eq!(on, left, "on at X{}", p[on].commanded.x);
    // The lines are collinear: the tool passes X10 without stopping, so
    // the output changed on the fly.
    assert!(p[on].velocity > 1.0, "{:?}", p[on]);
    let off = first(&p, |q| q.commanded.x > 20.0);
    assert!(p[left..off].iter().all(|q| q.digital & 1 == 1));
    assert!(p[off..].iter().all(|q| q.digital & 1 == 0));
}

#[test]
fn m64_and_m65_act_when_the_queue_reaches_them_with_the_tool_at_rest() {
    let p = run("G21 G90 G1 X10 F600\nM64 P1\nG1 X20\nM65 P1\nM2\n");
    let on = first(&p, |q| q.digital & 2 == 2);
    assert_eq!(p[on].commanded.x, 10.0);
    assert_eq!(p[on].velocity, 0.0);
    assert!(p[..on].iter().all(|q| q.commanded.x <= 10.0));
    let off = on + first(&p[on..], |q| q.digital & 2 == 0);
    assert_eq!(p[off].commanded.x, 20.0);
    assert!(p[on..off].iter().all(|q| q.digital & 2 == 2));
    // Nothing else moved.
    assert!(p.iter().all(|q| q.digital & !2 == 0));
}

#[test]
fn m67_sets_an_analog_output_with_the_next_move_and_m68_at_once() {
    let p = run("G21 G90 G1 X10 F600\nM67 E0 Q2.5\nM68 E1 Q-1.25\nG1 X20\nM2\n");
    // M68 stops the motion at X10 and acts there; M67, programmed before
    // it, still waits for the move after it.
    let immediate = first(&p, |q| q.analog[1] == -1.25);
    assert_eq!(p[immediate].commanded.x, 10.0);
    assert_eq!(p[immediate].analog[0], 0.0);
    let synced = first(&p, |q| q.analog[0] == 2.5);
    assert_eq!(synced, first(&p, |q| q.commanded.x > 10.0));
    assert_eq!(p.last().unwrap().analog, [2.5, -1.25]);
}

#[test]
fn m62_before_a_blended_corner_acts_where_the_blend_starts() {
    // G64 P0.05: the corner at X10 is rounded, so the tool never stands
    // at X10 Y0; the blend belongs to the move after M62.
    let p = run("G21 G90 G64 P0.05 G1 X10 F600\nM62 P3\nG1 Y10\nM2\n");
    let on = first(&p, |q| q.digital & 8 == 8);
    let c = p[on].commanded;
    assert!(c.x > 9.5 && c.x < 10.0 && c.y < 0.5, "on at {c:?}");
    assert!(p[on].velocity > 1.0);
    assert!(p[on..].iter().all(|q| q.digital & 8 == 8));
}

#[test]
fn output_numbers_are_checked_against_the_machine_when_planned() {
    let machine = kerf_machines::load("mill3").unwrap();
    let config = PlannerConfig {
        digital_outputs: 4,
        analog_outputs: 2,
        digital_inputs: 2,
        analog_inputs: 1,
        ..PlannerConfig::default()
    };
    let mut planner = Planner::new(&*machine.kinematics, Position::ZERO, config);
    let program = "G1 X1 F100\nM62 P4\nM68 E2 Q1\nM64 P3\nM66 P2 L3 Q1\nM66 P1 L3 Q1\nM2\n";
    let errors: Vec<String> = Interpreter::from_text(program, "bad.ngc", Position::ZERO)
        .filter_map(|c| planner.plan(&c.unwrap()).err())
        .map(|e| e.to_string())
        .collect();
    assert_eq!(errors.len(), 3, "{errors:?}");
    assert!(
        errors[0].contains("bad.ngc:2") && errors[0].contains("no digital output 4"),
        "{errors:?}"
    );
    assert!(
        errors[1].contains("bad.ngc:3") && errors[1].contains("no analog output 2"),
        "{errors:?}"
    );
    assert!(
        errors[2].contains("bad.ngc:5") && errors[2].contains("no digital input 2"),
        "{errors:?}"
    );
}

#[test]
fn m66_holds_the_tool_until_the_input_goes_high() {
    // The input rises in period 3000, long after the tool reached X10
    // (about 1 s at 600 mm/min); the tool waits there at rest, the answer
    // is 1, and the move to X20 starts in that same period.
    let p = run_with_input("G21 G90 G1 X10 F600\nM66 P0 L3 Q10\nG1 X20\nM2\n", |n| {
        n >= 3000
    });
    let answered = p
        .iter()
        .position(|q| q.inputs_answered == 1)
        .expect("never answered");
    assert_eq!(answered, 3000);
    assert_eq!(p[answered].input_value, 1.0);
    let arrived = p
        .iter()
        .position(|q| (q.commanded.x - 10.0).abs() < 1e-12)
        .unwrap();
    assert!(arrived < 2000, "{arrived}");
    for q in &p[arrived..answered] {
        assert!(
            (q.commanded.x - 10.0).abs() < 1e-12 && q.velocity == 0.0,
            "{q:?}"
        );
    }
    assert!(p[answered].commanded.x > 10.0);
    assert!((p.last().unwrap().commanded.x - 20.0).abs() < 1e-9);
}

#[test]
fn m66_times_out_with_minus_one_and_the_program_goes_on() {
    // Never high: after Q0.5 s of waiting the answer is −1 and the
    // program carries on to X20.
    let p = run_with_input("G21 G90 G1 X10 F600\nM66 P0 L3 Q0.5\nG1 X20\nM2\n", |_| {
        false
    });
    let arrived = p
        .iter()
        .position(|q| (q.commanded.x - 10.0).abs() < 1e-12)
        .unwrap();
    let answered = p
        .iter()
        .position(|q| q.inputs_answered == 1)
        .expect("never answered");
    assert_eq!(p[answered].input_value, -1.0);
    let waited = (answered - arrived) as f64 * 0.001;
    assert!((waited - 0.5).abs() <= 0.003, "waited {waited} s");
    assert!((p.last().unwrap().commanded.x - 20.0).abs() < 1e-9);
}
