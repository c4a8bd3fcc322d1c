//! The executor: advances along planned segments one servo period at a time.
//!
//! Real-time safe: [`Executor::tick`] neither allocates nor locks; segments
//! are `Copy` and come from a caller-supplied source (in the daemon, a
//! lock-free queue).

use kerf_interp::Position;

use crate::plan::Segment;

/// What the executor commands for one servo period.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Commanded tool position at the end of the period.
    pub position: Position,
    /// Source line of the segment being executed (or last executed).
    pub line: u32,
    /// True while a segment is in progress.
    pub moving: bool,
}

/// Follows a stream of segments in time.
#[derive(Clone, Debug)]
pub struct Executor {
    current: Option<Segment>,
    /// Time into the current segment, seconds.
    elapsed: f64,
    position: Position,
    line: u32,
}

impl Executor {
    /// An idle executor holding the tool at `start`.
    pub fn new(start: Position) -> Self {
        Executor {
            current: None,
            elapsed: 0.0,
            position: start,
            line: 0,
        }
    }

    /// The commanded position after the last tick.
    pub fn position(&self) -> Position {
        self.position
    }

    /// True when no segment is in progress.
    pub fn is_idle(&self) -> bool {
        self.current.is_none()
    }

    /// Advance by `dt` seconds, taking new segments from `next` as earlier
    /// ones finish. Time left over at the end of a segment carries into the
    /// next one, so no time is lost between segments.
    pub fn tick(&mut self, dt: f64, mut next: impl FnMut() -> Option<Segment>) -> Sample {
        let mut remaining = dt;
        loop {
            if self.current.is_none() {
                match next() {
                    Some(seg) => {
                        self.current = Some(seg);
                        self.elapsed = 0.0;
                        self.line = seg.line;
                    }
                    None => break,
                }
            }
            let seg = self.current.as_ref().expect("set above");
            let left = seg.duration() - self.elapsed;
            if remaining < left {
                self.elapsed += remaining;
                self.position = seg.position_at(self.elapsed);
                break;
            }
            remaining -= left.max(0.0);
            self.position = seg.end;
            self.current = None;
        }
        Sample {
            position: self.position,
            line: self.line,
            moving: self.current.is_some(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::SegmentKind;
    use crate::profile::Trapezoid;

    fn line(from: Position, to: Position, v: f64, a: f64, n: u32) -> Segment {
        let length =
            ((to.x - from.x).powi(2) + (to.y - from.y).powi(2) + (to.z - from.z).powi(2)).sqrt();
        Segment {
            kind: SegmentKind::Feed,
            line: n,
            start: from,
            end: to,
            profile: Trapezoid::new(length, v, a),
        }
    }

    #[test]
    fn runs_segments_back_to_back_and_ends_exactly() {
        let p0 = Position::ZERO;
        let p1 = Position::xyz(10.0, 0.0, 0.0);
        let p2 = Position::xyz(10.0, 5.0, 0.0);
        let mut queue = vec![line(p1, p2, 20.0, 200.0, 2), line(p0, p1, 20.0, 200.0, 1)];
        let total: f64 = queue.iter().map(|s| s.duration()).sum();
        let mut ex = Executor::new(p0);
        let dt = 0.001;
        let mut ticks = 0;
        loop {
            let s = ex.tick(dt, || queue.pop());
            ticks += 1;
            if !s.moving {
                assert_eq!(s.position, p2);
                assert_eq!(s.line, 2);
                break;
            }
            assert!(ticks < 100_000);
        }
        // Time carries over between segments: the run takes the planned time
        // rounded up to whole ticks.
        assert_eq!(ticks, (total / dt).ceil() as usize);
    }

    #[test]
    fn position_follows_the_profile() {
        let seg = line(Position::ZERO, Position::xyz(3.0, 4.0, 0.0), 10.0, 100.0, 7);
        let mut ex = Executor::new(Position::ZERO);
        let mut once = Some(seg);
        let s = ex.tick(0.05, || once.take());
        // 0.05 s into a ramp at 100 mm/s²: 0.125 mm along (3,4)/5.
        assert!((s.position.x - 0.075).abs() < 1e-12);
        assert!((s.position.y - 0.1).abs() < 1e-12);
        assert!(s.moving);
    }
}
