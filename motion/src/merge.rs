//! G64 Q: merging runs of nearly collinear straight feeds into one line,
//! as LinuxCNC's "naive CAM detector" does.
//!
//! CAM output often approximates straight edges with many tiny moves whose
//! points scatter a few microns about the line. Blending each of those tiny
//! corners is slow and pointless; with `G64 P.. Q..`, consecutive straight
//! feeds whose points all stay within Q of one straight line are replaced
//! by that line. The interpreter sends Q as
//! [`CanonCmd::SetNaivecamTolerance`] (Q defaults to P when only P is given,
//! and 0 disables merging).
//!
//! The rules follow LinuxCNC's `emccanon.cc` (`see_segment`, `linkable`,
//! `flush_segments`):
//!
//! * A chain starts with a straight feed in G64 with Q > 0. Each following
//!   straight feed joins it when the line from the chain's start to the new
//!   end point passes within Q of every point held so far (distance to the
//!   line segment, X Y Z), when it does not move A B C U V W, when it does
//!   not return to the chain's start, and when the chain holds at most 100
//!   points (so a merged line stands for at most 101 moves). There is no
//!   angle rule: a move that turns back still joins if its points stay
//!   within Q (an out-and-back wiggle shorter than Q vanishes).
//! * A move that does not join ends the chain: the chain is handed on as
//!   one line, and the move starts the next chain.
//! * A move of a rotary or U V W axis is handed on at once, never merged.
//! * A G17 arc whose chord deviation (sagitta) is below Q joins as two
//!   points, its midpoint and its end, like straight feeds (LinuxCNC does
//!   this in the XY plane only; kerf further requires a single turn).
//! * Every other command ends the chain first — rapids, other arcs, dwells,
//!   mode changes (G61, G64), M62–M68 outputs, M66, spindle, tool and
//!   offset changes, messages, program stops and ends — except those that
//!   cannot change the motion: a feed rate equal to the current one, a new
//!   Q (it applies to the next decision), comments, plane and unit
//!   selection, and the interpreter's print and log output.
//!
//! The merged line carries the source line of the last move it stands for
//! (as LinuxCNC's does), and the feed and outputs that applied to the moves
//! (every change of either ends the chain).

use std::collections::VecDeque;

use kerf_interp::{Canon, CanonCmd, Plane, Position, Source};

use crate::path::{distance_to_segment, Arc, Shape, Vec9};
use crate::plan::SourceMoves;

/// Most points a chain holds before a new move can no longer join it
/// (LinuxCNC's limit): one merged line stands for at most this many + 1
/// moves.
pub const MAX_CHAIN: usize = 100;

/// What the planner knows that decides whether a move may be merged.
#[derive(Clone, Copy, Debug)]
pub struct MergeContext {
    /// End of the last move the planner has planned (where a new chain
    /// starts when none is held).
    pub at: Position,
    /// G64 (blending) is in force.
    pub continuous: bool,
    /// The current feed rate is positive (a feed move at zero feed goes to
    /// the planner, which reports it).
    pub feed_ok: bool,
    /// The number the planner gave the command offered
    /// ([`SourceMoves`]): merged lines carry the numbers of the first and
    /// last moves they stand for.
    pub number: u64,
}

/// What the planner should do with the command it offered.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// The move joined the chain: nothing to plan for it now.
    Held,
    /// Plan the command as usual (after any merged lines from
    /// [`CollinearMerge::take`]).
    Pass,
}

/// The collinear merge in front of the planner's line handling.
#[derive(Clone, Debug, Default)]
pub struct CollinearMerge {
    /// Q, mm (0: off).
    tolerance: f64,
    /// The F word last seen, to tell a change from a repeat.
    feed_word: Option<f64>,
    /// Where the chain starts.
    start: Vec9,
    /// End points held, in order.
    points: Vec<Vec9>,
    /// Source of the last held move.
    source: Option<Source>,
    /// Numbers of the first and last held moves.
    moves: SourceMoves,
    /// Merged lines waiting to be planned, with the moves they stand for.
    out: VecDeque<(Canon, SourceMoves)>,
}

impl CollinearMerge {
    /// Merging off until a Q arrives.
    pub fn new() -> CollinearMerge {
        CollinearMerge::default()
    }

    /// The current Q, mm.
    pub fn tolerance(&self) -> f64 {
        self.tolerance
    }

    /// No move is held.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Offer the next command. Merged lines it releases are then available
    /// from [`take`](Self::take), to be planned before the command itself
    /// (if the verdict is [`Verdict::Pass`]).
    pub fn see(&mut self, canon: &Canon, ctx: &MergeContext) -> Verdict {
        let enabled = ctx.continuous && self.tolerance > 0.0 && ctx.feed_ok;
        match &canon.cmd {
            CanonCmd::StraightFeed { end } if enabled => {
                self.see_point(end.to_array(), &canon.source, ctx)
            }
            CanonCmd::ArcFeed {
                end,
                center,
                plane: Plane::XY,
                turns,
            } if enabled && turns.abs() == 1 => {
                let from = self.points.last().copied().unwrap_or(self.chain_start(ctx));
                let arc = Arc::from_program(
                    &from,
                    &end.to_array(),
                    (0, 1),
                    (center[0], center[1]),
                    *turns,
                );
                let half = arc.sweep.abs() / 2.0;
                let sagitta = arc.radius.max(arc.end_radius) * (1.0 - half.cos());
                if sagitta >= self.tolerance {
                    self.flush();
                    return Verdict::Pass;
                }
                let shape = Shape::Arc(arc);
                let mid = shape.point(shape.length() / 2.0);
                if self.see_point(mid, &canon.source, ctx) == Verdict::Pass {
                    // A rotary or U V W axis moves: the arc is not merged.
                    return Verdict::Pass;
                }
                self.see_point(end.to_array(), &canon.source, ctx)
            }
            CanonCmd::SetNaivecamTolerance { tolerance } => {
                self.tolerance = tolerance.max(0.0);
                Verdict::Pass
            }
            CanonCmd::SetFeedRate { mm_per_min } => {
                if self.feed_word != Some(*mm_per_min) {
                    self.flush();
                }
                self.feed_word = Some(*mm_per_min);
                Verdict::Pass
            }
            CanonCmd::Comment(_)
            | CanonCmd::SelectPlane(_)
            | CanonCmd::UseLengthUnits(_)
            | CanonCmd::Print(_)
            | CanonCmd::Log(_)
            | CanonCmd::LogOpen(_)
            | CanonCmd::LogAppend(_)
            | CanonCmd::LogClose => Verdict::Pass,
            _ => {
                self.flush();
                Verdict::Pass
            }
        }
    }

    /// A straight move to `end` (LinuxCNC's `see_segment`).
    fn see_point(&mut self, end: Vec9, source: &Source, ctx: &MergeContext) -> Verdict {
        let start = self.chain_start(ctx);
        let other_axes = |a: &Vec9, b: &Vec9| (3..9).any(|i| a[i] != b[i]);
        if other_axes(&start, &end) {
            // Never merged; what is held goes first.
            self.flush();
            return Verdict::Pass;
        }
        if !self.points.is_empty() && !self.linkable(&end) {
            self.flush();
        }
        if self.points.is_empty() {
            self.start = self.chain_start(ctx);
            self.moves.first = ctx.number;
        }
        self.points.push(end);
        self.source = Some(source.clone());
        self.moves.last = ctx.number;
        Verdict::Held
    }

    /// Where the chain starts, or would start: where the last move (held,
    /// just released, or planned) ends.
    fn chain_start(&self, ctx: &MergeContext) -> Vec9 {
        if !self.points.is_empty() {
            return self.start;
        }
        match self.out.back() {
            Some((
                Canon {
                    cmd: CanonCmd::StraightFeed { end },
                    ..
                },
                _,
            )) => end.to_array(),
            _ => ctx.at.to_array(),
        }
    }

    /// Start of the chain of held moves, if any.
    pub fn first(&self) -> Option<Position> {
        (!self.points.is_empty()).then(|| Position::from_array(self.start))
    }

    /// End of the last held move, if any.
    pub fn last(&self) -> Option<Position> {
        self.points.last().map(|p| Position::from_array(*p))
    }

    /// Whether a move to `end` can join the chain (LinuxCNC's `linkable`).
    fn linkable(&self, end: &Vec9) -> bool {
        if self.points.len() > MAX_CHAIN {
            return false;
        }
        if (0..3).all(|i| end[i] == self.start[i]) {
            return false;
        }
        self.points
            .iter()
            .all(|p| distance_to_segment(p, &self.start, end) <= self.tolerance)
    }

    /// Hand on what is held as one straight feed to the last point.
    pub fn flush(&mut self) {
        let Some(&last) = self.points.last() else {
            return;
        };
        let source = self.source.take().expect("a held move has a source");
        self.out.push_back((
            Canon {
                source,
                cmd: CanonCmd::StraightFeed {
                    end: Position::from_array(last),
                },
            },
            self.moves,
        ));
        self.points.clear();
    }

    /// The next merged line to plan, if any, with the numbers of the moves
    /// it stands for.
    pub fn take(&mut self) -> Option<(Canon, SourceMoves)> {
        self.out.pop_front()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kerf_interp::Interpreter;

    /// Run `text` through the merge alone: the straight feeds it hands on
    /// (held or passed), as (end X, end Y, source line).
    fn lines(text: &str) -> Vec<(f64, f64, u32)> {
        handed_on(text)
            .into_iter()
            .map(|(x, y, line, _)| (x, y, line))
            .collect()
    }

    /// [`lines`], with the numbers of the moves each stands for (canon
    /// commands numbered from 1, as the planner numbers them).
    fn handed_on(text: &str) -> Vec<(f64, f64, u32, SourceMoves)> {
        let mut merge = CollinearMerge::new();
        let mut at = Position::ZERO;
        let mut out = Vec::new();
        let note = |c: &Canon, moves, at: &mut Position, out: &mut Vec<_>| {
            if let CanonCmd::StraightFeed { end } | CanonCmd::ArcFeed { end, .. } = c.cmd {
                out.push((end.x, end.y, c.source.line, moves));
                *at = end;
            }
        };
        let text = format!("{text}M2\n");
        for (number, c) in (1..).zip(Interpreter::from_text(&text, "t.ngc", Position::ZERO)) {
            let c = c.unwrap();
            let ctx = MergeContext {
                at,
                continuous: true,
                feed_ok: true,
                number,
            };
            let verdict = merge.see(&c, &ctx);
            while let Some((m, moves)) = merge.take() {
                note(&m, moves, &mut at, &mut out);
            }
            if verdict == Verdict::Pass {
                let moves = SourceMoves {
                    first: number,
                    last: number,
                };
                note(&c, moves, &mut at, &mut out);
            }
        }
        merge.flush();
        while let Some((m, moves)) = merge.take() {
            note(&m, moves, &mut at, &mut out);
        }
        out
    }

    #[test]
    fn a_merged_line_stands_for_at_most_101_moves() {
        let mut text = "G21 G90 G64 P0.01 Q0.01 F600\n".to_string();
        for k in 1..=1000 {
            text += &format!("G1 X{}\n", k as f64 * 0.01);
        }
        let got = lines(&text);
        // 1000 collinear moves: chains of 101, the last of 91.
        assert_eq!(got.len(), 10, "{got:?}");
        assert!((got[0].0 - 1.01).abs() < 1e-9 && got[0].2 == 102);
        assert!((got[9].0 - 10.0).abs() < 1e-9 && got[9].2 == 1001);
    }

    #[test]
    fn a_merged_line_carries_the_numbers_of_the_first_and_last_moves_it_stands_for() {
        // Three collinear moves in a loop (one source line, three moves),
        // then a turn; the numbers are the moves' places in the canon
        // stream, counted here from the interpreter's own output.
        let text = "G21 G90 G64 P0.01 Q0.01 F600\n#1=1\nO1 while [#1 LE 3]\nG1 X#1\n#1=[#1+1]\nO1 endwhile\nG1 Y1\n";
        let feeds: Vec<u64> = (1..)
            .zip(Interpreter::from_text(
                format!("{text}M2\n"),
                "t.ngc",
                Position::ZERO,
            ))
            .filter(|(_, c)| matches!(c.as_ref().unwrap().cmd, CanonCmd::StraightFeed { .. }))
            .map(|(n, _)| n)
            .collect();
        assert_eq!(feeds.len(), 4, "three moves in the loop and one after");
        let got = handed_on(text);
        let span = |first, last| SourceMoves { first, last };
        assert_eq!(
            got,
            vec![
                (3.0, 0.0, 4, span(feeds[0], feeds[2])),
                (3.0, 1.0, 7, span(feeds[3], feeds[3])),
            ]
        );
    }

    #[test]
    fn merged_lines_stand_for_every_move_once_and_in_order() {
        // Flat arcs (joining as midpoint and end) among short lines that
        // wander within and beyond Q: whatever the chains, the numbers
        // handed on cover every move, in order, and only an arc split
        // between two chains appears in both.
        let mut text = "G21 G90 G64 P0.01 Q0.01 F600\n".to_string();
        let mut rng = crate::testkit::uniform(7);
        let (mut x, mut y) = (0.0, 0.0);
        for _ in 0..400 {
            x += 0.3;
            let dy = rng() * 0.02 - 0.01;
            if rng() < 0.25 {
                text += &format!("G3 X{x:.4} Y{:.4} R50\n", y + dy);
            } else {
                text += &format!("G1 X{x:.4} Y{:.4}\n", y + dy);
            }
            y += dy;
        }
        let moves: Vec<(u64, bool)> = (1..)
            .zip(Interpreter::from_text(
                format!("{text}M2\n"),
                "t.ngc",
                Position::ZERO,
            ))
            .filter_map(|(n, c)| match c.unwrap().cmd {
                CanonCmd::StraightFeed { .. } => Some((n, false)),
                CanonCmd::ArcFeed { .. } => Some((n, true)),
                _ => None,
            })
            .collect();
        let got = handed_on(&text);
        assert!(
            got.len() < moves.len() / 2,
            "most moves merge: {}",
            got.len()
        );
        let mut next = 0;
        for (k, m) in got.iter().enumerate() {
            let SourceMoves { first, last } = m.3;
            assert!(first <= last);
            // Starts at the next move, or on the arc the last one ended on.
            let shared = k > 0 && got[k - 1].3.last == first;
            assert!(
                moves[next].0 == first || (shared && moves[next - 1] == (first, true)),
                "line {k} ({first}..{last}) starts at move {:?}",
                moves[next]
            );
            while next < moves.len() && moves[next].0 <= last {
                next += 1;
            }
        }
        assert_eq!(next, moves.len(), "every move handed on");
        let shared = got.windows(2).filter(|w| w[0].3.last == w[1].3.first);
        assert!(shared.count() > 0, "the program splits some arc");
    }

    #[test]
    fn a_wiggle_within_q_vanishes_and_a_return_to_the_start_does_not() {
        // Out and back by less than Q: no angle rule, the points are all
        // within Q of the line from the start to X5.
        let got = lines("G21 G90 G64 P0.01 Q0.01 F600\nG1 X5\nX5.008\nX5\nX10\n");
        assert_eq!(got, vec![(10.0, 0.0, 5)]);
        // Back to the start of the chain: never linked (the line would
        // have no length), so the chain ends at X0.005; the next chain, from
        // there, takes the step back within Q.
        let got = lines("G21 G90 G64 P0.01 Q0.01 F600\nG1 X0.005\nX0\nX5\n");
        assert_eq!(got, vec![(0.005, 0.0, 2), (5.0, 0.0, 4)]);
    }

    #[test]
    fn a_rotary_move_is_never_merged_and_ends_the_chain() {
        let got = lines("G21 G90 G64 P0.01 Q0.01 F600\nG1 X1\nX2\nX3 A10\nX4\nX5\n");
        assert_eq!(got, vec![(2.0, 0.0, 3), (3.0, 0.0, 4), (5.0, 0.0, 6)]);
    }

    #[test]
    fn a_flat_g17_arc_joins_the_chain_and_a_round_one_ends_it() {
        // R 1000 over 1 mm: sagitta 0.000125 mm, below Q.
        let flat = "G21 G90 G64 P0.01 Q0.01 F600\nG1 X5\nG17 G2 X6 R1000\nG1 X10\n";
        assert_eq!(lines(flat), vec![(10.0, 0.0, 4)]);
        // R 2 over 1 mm: sagitta 0.063 mm, an arc as programmed.
        let round = "G21 G90 G64 P0.01 Q0.01 F600\nG1 X5\nG17 G2 X6 R2\nG1 X10\n";
        assert_eq!(
            lines(round),
            vec![(5.0, 0.0, 2), (6.0, 0.0, 3), (10.0, 0.0, 4)]
        );
        // The same flat arc in G18 is not merged (LinuxCNC: XY only).
        let g18 = "G21 G90 G64 P0.01 Q0.01 F600\nG1 X5\nG18 G2 X6 R1000\nG1 X10\n";
        assert_eq!(lines(g18).len(), 3);
    }
}
