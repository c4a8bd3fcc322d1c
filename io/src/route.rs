//! Routing joints to backends: the [`Hal`] that [`crate::build`] returns
//! when a machine mixes backends.

use crate::config::Wire;
use crate::{
    can, stepdir, Feedback, Hal, HalConfig, HalConfigError, HalFault, Setpoints, SimHal, MAX_JOINTS,
};

/// One backend and the machine joints it drives (its joint `i` is machine
/// joint `joints[i]`).
struct Part {
    hal: Box<dyn Hal>,
    joints: Vec<usize>,
}

/// Several backends behind one [`Hal`]: each tick every backend gets its
/// joints' setpoints (renumbered from 0) and its feedback is copied back.
struct Router {
    parts: Vec<Part>,
    joints: usize,
    local_out: Setpoints,
    local_fb: Feedback,
}

pub(crate) fn build(config: &HalConfig, initial: &[f64]) -> Result<Box<dyn Hal>, HalConfigError> {
    if initial.is_empty() || initial.len() > MAX_JOINTS {
        return Err(HalConfigError::key(
            "backend",
            format!(
                "the HAL drives 1 to {MAX_JOINTS} joints, asked for {}",
                initial.len()
            ),
        ));
    }
    let wires = config.wiring(initial.len())?;
    let pick = |f: &dyn Fn(Wire) -> bool| -> Vec<usize> {
        (0..wires.len()).filter(|&j| f(wires[j])).collect()
    };
    let mut parts = Vec::new();
    let sim = pick(&|w| w == Wire::Sim);
    if config.sim.cutting.is_some() && sim.len() != initial.len() {
        // The cutting process reads the tool tip from the simulated joints.
        return Err(HalConfigError::key(
            "sim.cutting",
            "the simulated cutting process needs every joint simulated",
        ));
    }
    if !sim.is_empty() {
        let at: Vec<f64> = sim.iter().map(|&j| initial[j]).collect();
        parts.push(Part {
            hal: Box::new(SimHal::new(&config.sim, &at)?),
            joints: sim,
        });
    }
    if let Some(sd) = &config.stepdir {
        sd.validate()?;
        let joints = pick(&|w| matches!(w, Wire::StepDir(_)));
        if !joints.is_empty() {
            let at: Vec<f64> = joints.iter().map(|&j| initial[j]).collect();
            // The entries in machine-joint order, so local joint i is joints[i].
            let mut ordered = sd.clone();
            ordered.joints.sort_by_key(|j| j.joint);
            parts.push(Part {
                hal: Box::new(stepdir::StepDirHal::open(&ordered, &at)?),
                joints,
            });
        }
    }
    if let Some(c) = &config.can {
        c.validate()?;
        let joints = pick(&|w| matches!(w, Wire::Can(_)));
        if !joints.is_empty() {
            let at: Vec<f64> = joints.iter().map(|&j| initial[j]).collect();
            let mut ordered = c.clone();
            ordered.drives.sort_by_key(|d| d.joint);
            parts.push(Part {
                hal: Box::new(can::CanHal::open(&ordered, &at)?),
                joints,
            });
        }
    }
    // One backend driving every joint in order needs no routing.
    if parts.len() == 1 {
        return Ok(parts.pop().expect("one part").hal);
    }
    Ok(Box::new(Router {
        parts,
        joints: initial.len(),
        local_out: Setpoints::default(),
        local_fb: Feedback::default(),
    }))
}

impl Hal for Router {
    fn name(&self) -> &str {
        "mixed"
    }

    fn joint_count(&self) -> usize {
        self.joints
    }

    fn exchange(
        &mut self,
        period: f64,
        out: &Setpoints,
        feedback: &mut Feedback,
    ) -> Result<(), HalFault> {
        let mut result = Ok(());
        feedback.spindle_current = 0.0;
        feedback.cutting_force = 0.0;
        self.local_out.enable = out.enable;
        self.local_out.spindle_speed = out.spindle_speed;
        for part in &mut self.parts {
            for (local, &global) in part.joints.iter().enumerate() {
                self.local_out.joints[local] = out.joints[global];
            }
            // Every backend is exchanged with even after another faulted, so
            // each sees the same ticks; the servo disables them all next tick.
            let r = part
                .hal
                .exchange(period, &self.local_out, &mut self.local_fb);
            for (local, &global) in part.joints.iter().enumerate() {
                feedback.joints[global] = self.local_fb.joints[local];
            }
            feedback.spindle_current += self.local_fb.spindle_current;
            feedback.cutting_force = feedback.cutting_force.max(self.local_fb.cutting_force);
            if let (Ok(()), Err(e)) = (&result, r) {
                result = Err(renumber(e, &part.joints));
            }
        }
        result
    }

    fn clear_fault(&mut self) -> Result<(), HalFault> {
        let mut result = Ok(());
        for part in &mut self.parts {
            if let Err(e) = part.hal.clear_fault() {
                result = result.and(Err(renumber(e, &part.joints)));
            }
        }
        result
    }
}

/// A backend's fault with its joint number turned into the machine's.
fn renumber(fault: HalFault, joints: &[usize]) -> HalFault {
    match fault {
        HalFault::Drive { joint, reason } => HalFault::Drive {
            joint: joints.get(joint).copied().unwrap_or(joint),
            reason,
        },
        link => link,
    }
}
