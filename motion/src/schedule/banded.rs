//! Linear programs whose constraint rows each touch at most [`WIDTH`]
//! neighbouring unknowns, as the schedule's do (a node, its neighbours
//! and, for the jerk between nodes, the node after next), solved by a
//! primal–dual interior-point method with Mehrotra's predictor–corrector.
//!
//! Why not a general solver: each Newton step of an interior-point method
//! solves the normal equations Gᵀ·W·G·Δx = r (W diagonal and positive).
//! With every row of G inside [`WIDTH`] neighbouring columns, Gᵀ·W·G is
//! banded ([`WIDTH`] − 1 diagonals each side), so its LDLᵀ factorisation
//! and both solves take time linear in the unknowns, and nothing but the rows and a few vectors is
//! stored. A general sparse solver (clarabel, which the schedule used
//! until 2026-11-27, and which the tests below still check it against)
//! orders, factors and refines a KKT system of rows and columns
//! together: on the schedule benchmark's programs it took 6–12 times as
//! long for the same schedules (`cargo bench --bench schedule`: the
//! circle 91 s against 7.9 s, stellabee1.ngc's first 2000 lines 71 s
//! against 11.6 s, both 54.266 s of motion).
//!
//! The method: from x = 0 with every slack and multiplier positive (an
//! infeasible start), each step solves the Newton system twice with one
//! factorisation, first for the affine direction, then for the centred
//! direction with its second-order correction, and moves the primal and
//! the dual variables each as far as keeps them positive (a share
//! [`STEP_SHARE`] of the way to the boundary).
//!
//! Scaling: rows enter divided by their largest coefficient and the
//! unknowns by a scale the caller gives (about their largest value), so
//! the tolerances below are relative.

/// Neighbouring columns a row may span.
pub(super) const WIDTH: usize = 4;

/// Stop when the scaled primal residual, dual residual and duality gap
/// are all below this.
const TOLERANCE: f64 = 1e-9;

/// Near the optimum the normal equations lose accuracy (W spans many
/// orders of magnitude), and the dual residual can grow again instead of
/// shrinking. The best iterate seen is then the answer if it is within
/// this (the primal residual, which the schedule's limits rest on, within
/// [`TOLERANCE`] still).
const ACCEPTABLE: f64 = 1e-6;

/// Newton steps before giving up.
const MOST_STEPS: usize = 200;

/// Fraction of the way to the boundary of the positive orthant a step
/// may go.
const STEP_SHARE: f64 = 0.995;

/// A pivot below this fraction of its own diagonal entry has lost its
/// digits to cancellation.
const PIVOT: f64 = 1e-15;

/// Refinement steps after each solve with the factors.
const REFINE: usize = 1;

/// `min c·x subject to G·x ≤ h`, each row of G nonzero only in
/// [`WIDTH`] neighbouring columns.
#[derive(Clone, Debug, Default)]
pub(super) struct BandedLp {
    columns: usize,
    /// First column of each row.
    first: Vec<usize>,
    /// Each row's coefficients in columns first, first + 1, ….
    coef: Vec<[f64; WIDTH]>,
    /// Each row's bound.
    rhs: Vec<f64>,
    /// Columns held at zero.
    fixed: Vec<usize>,
    /// A row with no terms and a negative bound was pushed.
    impossible: bool,
}

/// Why a linear program has no solution from [`BandedLp::solve`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Failure {
    /// A row's terms span more than [`WIDTH`] neighbouring columns, or
    /// name a column past the last.
    NotBanded,
    /// A row reads 0 ≤ a negative bound (on its own, or once the columns
    /// held at zero drop out of it).
    Infeasible,
    /// No convergence within [`MOST_STEPS`] Newton steps, or the
    /// arithmetic broke down (infeasible or unbounded programs that no
    /// single row gives away end here).
    NoConvergence,
}

impl BandedLp {
    /// A program in `columns` unknowns with no rows yet.
    pub(super) fn new(columns: usize) -> BandedLp {
        BandedLp {
            columns,
            ..BandedLp::default()
        }
    }

    /// Hold x[column] at zero. A pair of rows x ≤ 0 and −x ≤ 0 would say
    /// the same, but leave the rows no interior, which interior-point
    /// methods handle badly (both multipliers grow without bound).
    pub(super) fn fix_zero(&mut self, column: usize) {
        self.fixed.push(column);
    }

    /// Rows so far.
    pub(super) fn rows(&self) -> usize {
        self.rhs.len()
    }

    /// Add the row Σ value·x[column] ≤ `bound`. Terms naming one column
    /// twice are summed; zero terms are ignored.
    pub(super) fn push(&mut self, terms: &[(usize, f64)], bound: f64) -> Result<(), Failure> {
        if bound == f64::INFINITY {
            // Never binds.
            return Ok(());
        }
        let mut low = usize::MAX;
        let mut high = 0;
        for &(column, value) in terms {
            if value != 0.0 {
                low = low.min(column);
                high = high.max(column);
            }
        }
        if low == usize::MAX {
            // 0 ≤ bound: nothing to keep, but it may not hold.
            self.impossible |= bound < 0.0;
            return Ok(());
        }
        if high >= self.columns || high - low >= WIDTH {
            return Err(Failure::NotBanded);
        }
        // Rows near the last column start early enough to keep all their
        // columns in range (where there are that many).
        let first = low.min(self.columns.saturating_sub(WIDTH));
        let mut coef = [0.0; WIDTH];
        for &(column, value) in terms {
            if value != 0.0 {
                coef[column - first] += value;
            }
        }
        self.first.push(first);
        self.coef.push(coef);
        self.rhs.push(bound);
        Ok(())
    }

    /// The x that minimises `c·x` within the rows, with x entering the
    /// arithmetic divided by `scale` (about the largest |x| expected).
    pub(super) fn solve(&self, c: &[f64], scale: f64) -> Result<Vec<f64>, Failure> {
        let n = self.columns;
        assert_eq!(c.len(), n, "one objective coefficient per column");
        if self.impossible {
            return Err(Failure::Infeasible);
        }
        if n == 0 {
            return Ok(Vec::new());
        }
        let scale = if scale.is_finite() && scale > 0.0 {
            scale
        } else {
            1.0
        };
        // Scaled rows: x = scale·y, each row divided by its largest
        // coefficient; rows left with nothing but held columns drop out.
        // Columns of padding, held at zero, so that every row's columns
        // are in range and the row loops need no tests.
        let padded = n + WIDTH - 1;
        let mut held = vec![false; padded];
        held[n..].fill(true);
        for &column in &self.fixed {
            held[column] = true;
        }
        let m = self.rows();
        let mut first = Vec::with_capacity(m);
        let mut g = Vec::with_capacity(m);
        let mut h = Vec::with_capacity(m);
        for r in 0..m {
            let f = self.first[r];
            let row: [f64; WIDTH] = std::array::from_fn(|i| {
                if !held[f + i] {
                    self.coef[r][i] * scale
                } else {
                    0.0
                }
            });
            let big = row.iter().fold(0.0f64, |b, a| b.max(a.abs()));
            if big == 0.0 {
                // Only held columns: 0 ≤ bound.
                if self.rhs[r] < 0.0 {
                    return Err(Failure::Infeasible);
                }
                continue;
            }
            first.push(f);
            g.push(row.map(|a| a / big));
            h.push(self.rhs[r] / big);
        }
        // c·x = scale·(c·y): the objective in y, scaled to a largest
        // coefficient of 1 (which changes no minimiser).
        let c_big = (0..n)
            .filter(|&i| !held[i])
            .fold(0.0f64, |b, i| b.max(c[i].abs()));
        let c: Vec<f64> = (0..padded)
            .map(|i| {
                if held[i] || c_big == 0.0 {
                    0.0
                } else {
                    c[i] / c_big
                }
            })
            .collect();
        let problem = Scaled {
            n: padded,
            held: &held,
            first: &first,
            g: &g,
            h: &h,
            c: &c,
        };
        let y = problem.interior_point()?;
        Ok(y[..n].iter().map(|y| y * scale).collect())
    }
}

/// The program after scaling, and the method's working arithmetic.
struct Scaled<'a> {
    n: usize,
    /// Columns held at zero: no row touches them; their Newton step is 0.
    held: &'a [bool],
    first: &'a [usize],
    g: &'a [[f64; WIDTH]],
    h: &'a [f64],
    c: &'a [f64],
}

/// The banded normal matrix Gᵀ·W·G, factored in place as L·D·Lᵀ (L unit
/// lower triangular with [`WIDTH`] − 1 subdiagonals).
struct Banded {
    /// The matrix as assembled: `m[0]` the diagonal, `m[q][i]` = M[i + q][i],
    /// kept for iterative refinement.
    m: [Vec<f64>; WIDTH],
    /// The same, then D (`d[0]`) and L (`d[q][i]` = L[i + q][i]).
    d: [Vec<f64>; WIDTH],
}

impl Banded {
    fn zeros(n: usize) -> Banded {
        Banded {
            m: std::array::from_fn(|_| vec![0.0; n]),
            d: std::array::from_fn(|_| vec![0.0; n]),
        }
    }

    fn clear(&mut self) {
        for d in &mut self.d {
            d.fill(0.0);
        }
    }

    /// Add w·aᵀa for a row a in columns first..first + [`WIDTH`] (all in
    /// range).
    fn add_row(&mut self, first: usize, a: &[f64; WIDTH], w: f64) {
        for i in 0..WIDTH {
            let wa = w * a[i];
            for q in 0..WIDTH - i {
                self.d[q][first + i] += wa * a[i + q];
            }
        }
    }

    /// Factor in place. A pivot that cancellation has left below
    /// [`PIVOT`] of its diagonal entry (the matrix is singular to working
    /// precision along it) becomes huge, which zeroes that direction of
    /// the step: the usual remedy in interior-point codes, where such
    /// directions belong to rows whose multipliers have all but vanished.
    /// Measured against the entry's own diagonal, not the matrix's
    /// largest: W spans twenty orders of magnitude near the optimum, and
    /// a global threshold froze columns that still had a residual to
    /// remove (stellabee1.ngc's first 500 lines then failed a stretch).
    fn factor(&mut self) {
        let n = self.d[0].len();
        for (m, d) in self.m.iter_mut().zip(&self.d) {
            m.copy_from_slice(d);
        }
        let d = &mut self.d;
        for i in 0..n {
            // Column i: D_i, then L[i + r][i] for r = 1, 2, ….
            let mut pivot = d[0][i];
            for q in 1..WIDTH.min(i + 1) {
                let l = d[q][i - q];
                pivot -= l * l * d[0][i - q];
            }
            // NaN fails both tests and is caught with the rest.
            let sound = pivot > PIVOT * self.m[0][i] && pivot > f64::MIN_POSITIVE;
            if !sound {
                pivot = 1e128;
            }
            d[0][i] = pivot;
            for r in 1..WIDTH {
                // L[i + r][i]·D_i = M[i + r][i] − Σ_q L[i + r][i − q]·L[i][i − q]·D_{i−q}.
                let mut l = d[r][i];
                for q in 1..(WIDTH - r).min(i + 1) {
                    l -= d[r + q][i - q] * d[q][i - q] * d[0][i - q];
                }
                d[r][i] = l / pivot;
            }
        }
    }

    /// Solve the assembled system M·x = b in place: the factors' solution
    /// refined against M itself ([`REFINE`] times), which wins back digits
    /// the factorisation lost where W spans many orders of magnitude.
    /// `work` is scratch (two vectors' worth).
    fn solve_refined(&self, b: &mut [f64], work: &mut Vec<f64>) {
        let n = b.len();
        work.clear();
        work.extend_from_slice(b);
        work.resize(2 * n, 0.0);
        let (rhs, r) = work.split_at_mut(n);
        self.solve(b);
        for _ in 0..REFINE {
            // r = rhs − M·x, then x += M⁻¹·r.
            for i in 0..n {
                let mut mx = self.m[0][i] * b[i];
                for q in 1..WIDTH {
                    if i + q < n {
                        mx += self.m[q][i] * b[i + q];
                    }
                    if i >= q {
                        mx += self.m[q][i - q] * b[i - q];
                    }
                }
                r[i] = rhs[i] - mx;
            }
            self.solve(r);
            for i in 0..n {
                b[i] += r[i];
            }
        }
    }

    /// Solve L·D·Lᵀ·x = b in place.
    fn solve(&self, b: &mut [f64]) {
        let n = b.len();
        let d = &self.d;
        for i in 0..n {
            for q in 1..WIDTH.min(i + 1) {
                b[i] -= d[q][i - q] * b[i - q];
            }
        }
        for i in 0..n {
            b[i] /= d[0][i];
        }
        for i in (0..n).rev() {
            for q in 1..WIDTH {
                if i + q < n {
                    b[i] -= d[q][i] * b[i + q];
                }
            }
        }
    }
}

/// Largest α ≤ 1 with v + α·dv ≥ 0 everywhere.
fn step_to_boundary(v: &[f64], dv: &[f64]) -> f64 {
    let mut alpha = 1.0f64;
    for (v, dv) in v.iter().zip(dv) {
        if *dv < 0.0 {
            alpha = alpha.min(-v / dv);
        }
    }
    alpha
}

impl Scaled<'_> {
    /// Row r of G times x.
    fn row_times(&self, r: usize, x: &[f64]) -> f64 {
        let (f, a) = (self.first[r], &self.g[r]);
        a.iter().zip(&x[f..f + WIDTH]).map(|(a, x)| a * x).sum()
    }

    /// out += v times row r of G (transposed).
    fn add_row_times(&self, r: usize, v: f64, out: &mut [f64]) {
        let (f, a) = (self.first[r], &self.g[r]);
        for (out, a) in out[f..f + WIDTH].iter_mut().zip(a) {
            *out += a * v;
        }
    }

    fn interior_point(&self) -> Result<Vec<f64>, Failure> {
        let (n, m) = (self.n, self.h.len());
        if m == 0 {
            // No rows: bounded only if there is nothing to gain.
            return if self.c.iter().all(|&c| c == 0.0) {
                Ok(vec![0.0; n])
            } else {
                Err(Failure::NoConvergence)
            };
        }
        let mut x = vec![0.0; n];
        let mut s: Vec<f64> = self.h.iter().map(|&h| h.max(1.0)).collect();
        let mut z = vec![1.0; m];
        let c_size = 1.0 + self.c.iter().fold(0.0f64, |b, c| b.max(c.abs()));

        let mut rp = vec![0.0; m];
        let mut rd = vec![0.0; n];
        let mut rc = vec![0.0; m];
        let mut t = vec![0.0; m];
        let mut dx = vec![0.0; n];
        let mut ds = vec![0.0; m];
        let mut dz = vec![0.0; m];
        let mut normal = Banded::zeros(n);
        let mut refine = Vec::with_capacity(n);
        // The iterate with the smallest dual residual and gap among those
        // primal feasible to the tolerance, and its step.
        let mut best = (f64::INFINITY, 0);
        let mut best_x = vec![0.0; n];

        for step in 0..MOST_STEPS {
            // One sweep over the rows for G·x, Gᵀ·z and the normal
            // matrix Gᵀ·W·G: the rows are the bulk of the memory this
            // reads, and three sweeps of them cost about a quarter more.
            // (The matrix goes unused on the step that returns.)
            rd.copy_from_slice(self.c);
            normal.clear();
            for r in 0..m {
                rp[r] = self.row_times(r, &x) + s[r] - self.h[r];
                self.add_row_times(r, z[r], &mut rd);
                normal.add_row(self.first[r], &self.g[r], z[r] / s[r]);
            }
            let gap: f64 = s.iter().zip(&z).map(|(s, z)| s * z).sum();
            let mu = gap / m as f64;
            let objective: f64 = self.c.iter().zip(&x).map(|(c, x)| c * x).sum();
            // Row by row against its own bound: the schedule's limits are
            // its rows, and a residual judged against the largest bound of
            // a stretch would let rows with small bounds (slow stretches)
            // be broken by more than the tolerance.
            let p_res = rp
                .iter()
                .zip(self.h)
                .fold(0.0f64, |b, (r, h)| b.max(r.abs() / (1.0 + h.abs())));
            let d_res = rd.iter().fold(0.0f64, |b, r| b.max(r.abs())) / c_size;
            if !(p_res.is_finite() && d_res.is_finite() && gap.is_finite()) {
                return Err(Failure::NoConvergence);
            }
            let gap_res = gap / (1.0 + objective.abs());
            if p_res < TOLERANCE && d_res < TOLERANCE && gap_res < TOLERANCE {
                return Ok(x);
            }
            let merit = d_res.max(gap_res);
            if p_res < TOLERANCE && merit < best.0 {
                best = (merit, step);
                best_x.copy_from_slice(&x);
            } else if best.0 < ACCEPTABLE && (merit > 1e3 * best.0 || step > best.1 + 20) {
                // Diverging or stalled past an acceptable point.
                return Ok(best_x);
            }

            for (i, held) in self.held.iter().enumerate() {
                if *held {
                    normal.d[0][i] = 1.0;
                }
            }
            normal.factor();

            // The Newton direction for complementarity target r_c:
            // Gᵀ·W·G·Δx = −r_d + Gᵀ·S⁻¹·(r_c − Z·r_p), then Δs and Δz.
            let mut direction =
                |rc: &[f64], t: &mut [f64], dx: &mut [f64], ds: &mut [f64], dz: &mut [f64]| {
                    // Row by row, each sweep doing all it can with the row in
                    // hand (see the sweep at the top of the step).
                    for (dx, rd) in dx.iter_mut().zip(&rd) {
                        *dx = -rd;
                    }
                    for r in 0..m {
                        t[r] = (rc[r] - z[r] * rp[r]) / s[r];
                        self.add_row_times(r, t[r], dx);
                    }
                    normal.solve_refined(dx, &mut refine);
                    for r in 0..m {
                        ds[r] = -rp[r] - self.row_times(r, dx);
                        dz[r] = -(rc[r] + z[r] * ds[r]) / s[r];
                    }
                };

            // Predictor: the affine-scaling direction.
            for r in 0..m {
                rc[r] = s[r] * z[r];
            }
            direction(&rc, &mut t, &mut dx, &mut ds, &mut dz);
            let (ap, ad) = (step_to_boundary(&s, &ds), step_to_boundary(&z, &dz));
            let affine_gap: f64 = (0..m)
                .map(|r| (s[r] + ap * ds[r]) * (z[r] + ad * dz[r]))
                .sum();
            let sigma = (affine_gap / gap).clamp(0.0, 1.0).powi(3);

            // Corrector: centred, with the predictor's second-order term.
            for r in 0..m {
                rc[r] = s[r] * z[r] + ds[r] * dz[r] - sigma * mu;
            }
            direction(&rc, &mut t, &mut dx, &mut ds, &mut dz);
            let ap = (STEP_SHARE * step_to_boundary(&s, &ds)).min(1.0);
            let ad = (STEP_SHARE * step_to_boundary(&z, &dz)).min(1.0);
            for i in 0..n {
                x[i] += ap * dx[i];
            }
            for r in 0..m {
                s[r] += ap * ds[r];
                z[r] += ad * dz[r];
            }
        }
        if best.0 < ACCEPTABLE {
            return Ok(best_x);
        }
        Err(Failure::NoConvergence)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_small_program_reaches_its_vertex() {
        // max x0 + x1 + x2 with x ≤ 1 each and x0 + x1 ≤ 1.5, x1 + x2 ≤ 1.2:
        // x1 as small as the sums allow: x0 = 1, x2 = 1, x1 = 0.2 (sum 2.2).
        let mut lp = BandedLp::new(3);
        for k in 0..3 {
            lp.push(&[(k, 1.0)], 1.0).unwrap();
            lp.push(&[(k, -1.0)], 0.0).unwrap();
        }
        lp.push(&[(0, 1.0), (1, 1.0)], 1.5).unwrap();
        lp.push(&[(1, 1.0), (2, 1.0)], 1.2).unwrap();
        let x = lp.solve(&[-1.0, -1.0, -1.0], 1.0).unwrap();
        let sum: f64 = x.iter().sum();
        assert!((sum - 2.2).abs() < 1e-8, "{x:?}");
        assert!(
            x[0] + x[1] <= 1.5 + 1e-9 && x[1] + x[2] <= 1.2 + 1e-9,
            "{x:?}"
        );
    }

    #[test]
    fn rows_wider_than_the_band_are_refused() {
        let mut lp = BandedLp::new(6);
        assert_eq!(
            lp.push(&[(0, 1.0), (WIDTH, 1.0)], 1.0),
            Err(Failure::NotBanded)
        );
        assert_eq!(lp.push(&[(6, 1.0)], 1.0), Err(Failure::NotBanded));
        assert_eq!(lp.rows(), 0);
    }

    #[test]
    fn an_unbounded_program_fails_rather_than_answering() {
        let mut lp = BandedLp::new(2);
        lp.push(&[(0, -1.0)], 0.0).unwrap();
        lp.push(&[(1, -1.0)], 0.0).unwrap();
        assert!(lp.solve(&[-1.0, 0.0], 1.0).is_err());
    }

    #[test]
    fn an_infeasible_program_fails_rather_than_answering() {
        let mut lp = BandedLp::new(3);
        lp.push(&[(1, 1.0)], -1.0).unwrap();
        lp.push(&[(1, -1.0)], 0.0).unwrap();
        assert!(lp.solve(&[0.0, -1.0, 0.0], 1.0).is_err());
        // A row that holding a column at zero leaves impossible.
        let mut lp = BandedLp::new(3);
        lp.fix_zero(1);
        lp.push(&[(1, 1.0)], -1.0).unwrap();
        assert_eq!(lp.solve(&[0.0; 3], 1.0), Err(Failure::Infeasible));
        let mut lp = BandedLp::new(3);
        lp.push(&[(1, 0.0)], -1.0).unwrap();
        assert_eq!(lp.solve(&[0.0; 3], 1.0), Err(Failure::Infeasible));
    }

    /// A row as the tests keep it: first column, coefficients, bound.
    type Row = (usize, [f64; WIDTH], f64);

    /// A random program shaped like the schedule's: 0 ≤ x ≤ cap at every
    /// column, and pairs |a·x| ≤ b over three and four neighbouring
    /// columns; its objective and rows.
    fn random_program(seed: u64, n: usize) -> (BandedLp, Vec<f64>, Vec<Row>) {
        let mut seed = seed;
        let mut rand = move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut lp = BandedLp::new(n);
        let mut rows = Vec::new();
        for k in 0..n {
            let cap = 0.5 + 100.0 * rand();
            lp.push(&[(k, 1.0)], cap).unwrap();
            lp.push(&[(k, -1.0)], 0.0).unwrap();
            rows.push((k, [1.0, 0.0, 0.0, 0.0], cap));
            rows.push((k, [-1.0, 0.0, 0.0, 0.0], 0.0));
        }
        for k in 1..n - 1 {
            for _ in 0..4 {
                let a = [rand() - 0.5, 2.0 * rand() - 1.0, rand() - 0.5].map(|v| v * 10.0);
                let b = 5.0 + 50.0 * rand();
                for sign in [1.0, -1.0] {
                    let terms = [(k - 1, sign * a[0]), (k, sign * a[1]), (k + 1, sign * a[2])];
                    lp.push(&terms, b).unwrap();
                    let a = a.map(|v| v * sign);
                    rows.push((k - 1, [a[0], a[1], a[2], 0.0], b));
                }
            }
        }
        // And rows over four columns, as the jerk between nodes makes.
        for k in 1..n - 2 {
            let a: [f64; 4] = std::array::from_fn(|_| 10.0 * (rand() - 0.5));
            let b = 5.0 + 50.0 * rand();
            for sign in [1.0, -1.0] {
                let a = a.map(|v| v * sign);
                let terms: [(usize, f64); 4] = std::array::from_fn(|i| (k - 1 + i, a[i]));
                lp.push(&terms, b).unwrap();
                rows.push((k - 1, a, b));
            }
        }
        let c: Vec<f64> = (0..n).map(|_| -0.1 - rand()).collect();
        (lp, c, rows)
    }

    #[test]
    fn random_programs_reach_the_optimum_a_general_solver_finds() {
        use clarabel::algebra::CscMatrix;
        use clarabel::solver::{
            DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
        };
        for seed in 1..=12u64 {
            let n = 20 + 15 * seed as usize;
            let (lp, c, rows) = random_program(seed, n);
            let x = lp.solve(&c, 100.0).expect("a bounded, feasible program");
            // Within every row.
            for (f, a, b) in &rows {
                let ax: f64 = (0..WIDTH)
                    .filter(|&i| f + i < n)
                    .map(|i| a[i] * x[f + i])
                    .sum();
                assert!(
                    ax <= b + 1e-7 * (1.0 + b.abs()),
                    "seed {seed}: row at {f}: {ax} > {b}"
                );
            }
            let ours: f64 = c.iter().zip(&x).map(|(c, x)| c * x).sum();
            // The same program in clarabel's terms: A·x + s = b, s ≥ 0.
            let mut entries: Vec<(usize, usize, f64)> = Vec::new();
            for (r, (f, a, _)) in rows.iter().enumerate() {
                for i in 0..WIDTH {
                    if f + i < n && a[i] != 0.0 {
                        entries.push((f + i, r, a[i]));
                    }
                }
            }
            entries.sort_unstable_by_key(|&(col, row, _)| (col, row));
            let mut colptr = vec![0; n + 1];
            let (mut rowval, mut nzval) = (Vec::new(), Vec::new());
            for &(col, row, v) in &entries {
                rowval.push(row);
                nzval.push(v);
                colptr[col + 1] = rowval.len();
            }
            for col in 1..=n {
                colptr[col] = colptr[col].max(colptr[col - 1]);
            }
            let a = CscMatrix::new(rows.len(), n, colptr, rowval, nzval);
            let b: Vec<f64> = rows.iter().map(|r| r.2).collect();
            let p = CscMatrix::zeros((n, n));
            let cones = [SupportedConeT::NonnegativeConeT(rows.len())];
            let settings = DefaultSettingsBuilder::default()
                .verbose(false)
                .build()
                .unwrap();
            let mut solver = DefaultSolver::new(&p, &c, &a, &b, &cones, settings).unwrap();
            solver.solve();
            assert_eq!(solver.solution.status, SolverStatus::Solved, "seed {seed}");
            let theirs = solver.solution.obj_val;
            assert!(
                (ours - theirs).abs() <= 1e-6 * theirs.abs(),
                "seed {seed}, {n} columns: {ours} against clarabel's {theirs}"
            );
        }
    }

    #[test]
    fn the_banded_factorisation_solves_its_matrix() {
        // M = Gᵀ·W·G for a random banded G, and M·x = b checked directly.
        let mut seed = 12345u64;
        let mut rand = move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let n = 40;
        let rows: Vec<(usize, [f64; WIDTH], f64)> = (0..160)
            .map(|r| {
                (
                    (r % (n + 1 - WIDTH)),
                    std::array::from_fn(|_| rand() - 0.5),
                    0.1 + rand(),
                )
            })
            .collect();
        let mut m = Banded::zeros(n);
        let mut dense = vec![vec![0.0; n]; n];
        for (f, a, w) in &rows {
            m.add_row(*f, a, *w);
            for i in 0..WIDTH {
                for j in 0..WIDTH {
                    dense[f + i][f + j] += w * a[i] * a[j];
                }
            }
        }
        let b: Vec<f64> = (0..n).map(|_| rand() - 0.5).collect();
        let mut x = b.clone();
        m.factor();
        m.solve(&mut x);
        for i in 0..n {
            let mx: f64 = (0..n).map(|j| dense[i][j] * x[j]).sum();
            assert!((mx - b[i]).abs() < 1e-9, "row {i}: {mx} against {}", b[i]);
        }
    }
}
