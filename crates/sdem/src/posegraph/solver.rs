//! The Levenberg–Marquardt solver over the free nodes: the factors, the sparse structure of the
//! normal equations and the damped steps (see the module documentation of [`super`]).

use super::{se3_exp, se3_log, Edge, OptimizeConfig, OptimizeReport, PoseGraph};
use crate::error::{Error, Result};
use crate::geometry::Pose;
use nalgebra::{DVector, Matrix6, Vector6};
use nalgebra_sparse::factorization::{CscCholesky, CscSymbolicCholesky};
use nalgebra_sparse::pattern::SparsityPattern;

/// An edge prepared for the solver.
struct Factor {
    from: usize,
    to: usize,
    /// `from_from_to⁻¹`.
    to_from_measured: Pose,
    information: Matrix6<f64>,
    /// Start (in the CSC values) of the blocks `(from, from)`, `(to, to)`, `(from, to)` (row
    /// `from`, column `to`) and `(to, from)`, where both nodes are free.
    block_ff: Option<Block>,
    block_tt: Option<Block>,
    block_ft: Option<Block>,
    block_tf: Option<Block>,
}

/// Where a 6×6 block lies in the CSC values: entry `(a, b)` is at `start + b * stride + a`.
#[derive(Clone, Copy)]
struct Block {
    start: usize,
    stride: usize,
}

impl Block {
    fn add(&self, values: &mut [f64], m: &Matrix6<f64>) {
        for b in 0..6 {
            let column = self.start + b * self.stride;
            for a in 0..6 {
                values[column + a] += m[(a, b)];
            }
        }
    }
}

/// The sparse structure of the normal equations over the free nodes.
struct Structure {
    /// Variable index of each node; `None` for the held ones.
    variable: Vec<Option<usize>>,
    pattern: SparsityPattern,
    /// The diagonal blocks of each variable.
    diagonal: Vec<Block>,
}

fn build_structure(held: &[bool], edges: &[Edge]) -> Result<Structure> {
    let mut variables = 0;
    let variable: Vec<Option<usize>> = held
        .iter()
        .map(|&is_held| {
            (!is_held).then(|| {
                variables += 1;
                variables - 1
            })
        })
        .collect();
    let mut rows: Vec<Vec<usize>> = (0..variables).map(|v| vec![v]).collect();
    for edge in edges {
        if let (Some(i), Some(j)) = (variable[edge.from], variable[edge.to]) {
            rows[i].push(j);
            rows[j].push(i);
        }
    }
    let mut offsets = Vec::with_capacity(6 * variables + 1);
    let mut indices = Vec::new();
    offsets.push(0);
    for column_rows in rows.iter_mut() {
        column_rows.sort_unstable();
        column_rows.dedup();
        for _ in 0..6 {
            for &row in column_rows.iter() {
                indices.extend(6 * row..6 * row + 6);
            }
            offsets.push(indices.len());
        }
    }
    let pattern = SparsityPattern::try_from_offsets_and_indices(
        6 * variables,
        6 * variables,
        offsets.clone(),
        indices,
    )
    .map_err(|e| Error::Invalid(format!("pose graph: internal sparsity pattern error: {e}")))?;
    let diagonal = (0..variables)
        .map(|v| block_of(&rows, &offsets, v, v))
        .collect();
    Ok(Structure {
        variable,
        pattern,
        diagonal,
    })
}

/// The block at block-row `row`, block-column `column`.
fn block_of(rows: &[Vec<usize>], offsets: &[usize], row: usize, column: usize) -> Block {
    let position = rows[column]
        .binary_search(&row)
        .expect("every edge's blocks are in the pattern");
    Block {
        start: offsets[6 * column] + 6 * position,
        stride: 6 * rows[column].len(),
    }
}

fn prepare_factors(
    graph: &PoseGraph,
    structure: &Structure,
    informations: Vec<Matrix6<f64>>,
) -> Vec<Factor> {
    // Rebuild the sorted block rows per column from the pattern: block row r is present in
    // block column c iff scalar row 6r is in scalar column 6c.
    let pattern = &structure.pattern;
    let variables = structure.diagonal.len();
    let rows: Vec<Vec<usize>> = (0..variables)
        .map(|c| {
            pattern
                .lane(6 * c)
                .iter()
                .step_by(6)
                .map(|r| r / 6)
                .collect()
        })
        .collect();
    let offsets = pattern.major_offsets();
    graph
        .edges
        .iter()
        .zip(informations)
        .map(|(edge, information)| {
            let i = structure.variable[edge.from];
            let j = structure.variable[edge.to];
            let pair = |a: Option<usize>, b: Option<usize>| match (a, b) {
                (Some(a), Some(b)) => Some(block_of(&rows, offsets, a, b)),
                _ => None,
            };
            Factor {
                from: edge.from,
                to: edge.to,
                to_from_measured: edge.from_from_to.inverse(),
                information,
                block_ff: pair(i, i),
                block_tt: pair(j, j),
                block_ft: pair(i, j),
                block_tf: pair(j, i),
            }
        })
        .collect()
}

/// `(ρ(s²), weight)` of the Cauchy kernel of width `c` at squared norm `s2`.
fn cauchy(s2: f64, c: f64) -> (f64, f64) {
    if c.is_infinite() {
        (s2, 1.0)
    } else {
        let c2 = c * c;
        (c2 * (s2 / c2).ln_1p(), 1.0 / (1.0 + s2 / c2))
    }
}

fn squared_norm(r: &Vector6<f64>, information: &Matrix6<f64>) -> f64 {
    r.dot(&(information * r)).max(0.0)
}

/// The robust cost and each edge's squared Mahalanobis norm.
fn evaluate(factors: &[Factor], poses: &[Pose], c: f64, s2: &mut Vec<f64>) -> f64 {
    s2.clear();
    let mut cost = 0.0;
    for f in factors {
        let r = se3_log(&(f.to_from_measured * poses[f.from].inverse() * poses[f.to]));
        let value = squared_norm(&r, &f.information);
        s2.push(value);
        cost += cauchy(value, c).0;
    }
    cost
}

/// Central-difference step for the Jacobians (radians and metres).
const JACOBIAN_STEP: f64 = 1e-6;

/// The residual and its Jacobians with respect to right updates of the two nodes.
fn linearize(f: &Factor, poses: &[Pose]) -> (Vector6<f64>, Matrix6<f64>, Matrix6<f64>) {
    let a = f.to_from_measured;
    let b = poses[f.from].inverse() * poses[f.to];
    let ab = a * b;
    let r = se3_log(&ab);
    let mut j_from = Matrix6::zeros();
    let mut j_to = Matrix6::zeros();
    for k in 0..6 {
        let mut delta = Vector6::zeros();
        delta[k] = JACOBIAN_STEP;
        let plus = se3_exp(&delta);
        let minus = se3_exp(&-delta);
        // (world_from_from · E)⁻¹ · world_from_to = E⁻¹ · b.
        let d_from = se3_log(&(a * plus.inverse() * b)) - se3_log(&(a * minus.inverse() * b));
        j_from.set_column(k, &(d_from / (2.0 * JACOBIAN_STEP)));
        let d_to = se3_log(&(ab * plus)) - se3_log(&(ab * minus));
        j_to.set_column(k, &(d_to / (2.0 * JACOBIAN_STEP)));
    }
    (r, j_from, j_to)
}

/// `gradient[6v..6v+6] += g`.
fn add_rows(gradient: &mut DVector<f64>, v: usize, g: &Vector6<f64>) {
    for a in 0..6 {
        gradient[6 * v + a] += g[a];
    }
}

/// Cost per edge under which a graph counts as exactly satisfied (a Mahalanobis norm of 1e-10).
const EXACT_COST_PER_EDGE: f64 = 1e-20;

/// Largest damping before giving up on lowering the cost.
const MAX_DAMPING: f64 = 1e16;

/// Each graduated stage narrows the kernel by this factor.
const GRADUATION_FACTOR: f64 = 4.0;

/// Relative cost decrease that ends an intermediate graduated stage.
const STAGE_TOLERANCE: f64 = 1e-3;

/// The Levenberg–Marquardt state over one graph.
struct Solver<'a> {
    factors: &'a [Factor],
    structure: &'a Structure,
    symbolic: CscSymbolicCholesky,
    factorization: Option<CscCholesky<f64>>,
    hessian: Vec<f64>,
    damped: Vec<f64>,
    gradient: DVector<f64>,
    poses: Vec<Pose>,
    candidate: Vec<Pose>,
    /// Squared Mahalanobis norm of each edge at `poses`.
    s2: Vec<f64>,
    candidate_s2: Vec<f64>,
    damping: f64,
    nu: f64,
    /// Cost under which the graph counts as exactly satisfied.
    exact_cost: f64,
}

impl Solver<'_> {
    /// The robust cost at the current poses for kernel width `c`.
    fn cost(&self, c: f64) -> f64 {
        self.s2.iter().map(|&v| cauchy(v, c).0).sum()
    }

    /// Runs Levenberg–Marquardt at kernel width `c` for at most `budget` iterations.
    ///
    /// # Returns
    /// The iterations used and whether the relative cost decrease fell under `tolerance` (or
    /// the cost is exact, or no step can lower it).
    fn run(&mut self, c: f64, tolerance: f64, budget: usize) -> (usize, bool) {
        let mut cost = self.cost(c);
        let mut iterations = 0;
        let mut converged = cost <= self.exact_cost || self.gradient.is_empty();
        while !converged && iterations < budget {
            iterations += 1;
            self.build_normal_equations(c);
            // Marquardt scaling: damp each unknown by its own curvature (floored, so an unknown
            // with no information cannot make the system singular).
            let scaling: Vec<f64> = self
                .structure
                .diagonal
                .iter()
                .flat_map(|block| (0..6).map(move |a| block.start + a * block.stride + a))
                .map(|index| self.hessian[index].max(1e-9))
                .collect();
            let mut accepted = false;
            while self.damping < MAX_DAMPING {
                let Some(step) = self.solve_damped(&scaling) else {
                    self.damping *= self.nu;
                    self.nu *= 2.0;
                    continue;
                };
                for (node, pose) in self.poses.iter().enumerate() {
                    self.candidate[node] = match self.structure.variable[node] {
                        Some(v) => pose * se3_exp(&Vector6::from_fn(|a, _| step[6 * v + a])),
                        None => *pose,
                    };
                }
                let candidate_cost =
                    evaluate(self.factors, &self.candidate, c, &mut self.candidate_s2);
                // Decrease predicted by the quadratic model F ≈ F₀ + 2 gᵀδ + δᵀHδ, using
                // (H + λD) δ = −g.
                let predicted = -self.gradient.dot(&step)
                    + self.damping
                        * step
                            .iter()
                            .zip(&scaling)
                            .map(|(d, s)| s * d * d)
                            .sum::<f64>();
                let decrease = cost - candidate_cost;
                if candidate_cost.is_finite() && decrease > 0.0 {
                    let gain = if predicted > 0.0 {
                        decrease / predicted
                    } else {
                        1.0
                    };
                    self.damping *= (1.0 - (2.0 * gain - 1.0).powi(3)).max(1.0 / 3.0);
                    self.damping = self.damping.max(1e-12);
                    self.nu = 2.0;
                    std::mem::swap(&mut self.poses, &mut self.candidate);
                    std::mem::swap(&mut self.s2, &mut self.candidate_s2);
                    cost = candidate_cost;
                    converged =
                        decrease <= tolerance * (cost + decrease) || cost <= self.exact_cost;
                    accepted = true;
                    break;
                }
                self.damping *= self.nu;
                self.nu *= 2.0;
            }
            if !accepted {
                // No step lowers the cost: a minimum to numerical precision. Start the next
                // stage from a usable damping.
                converged = true;
                self.damping = self.damping.min(1.0);
                self.nu = 2.0;
            }
        }
        (iterations, converged)
    }

    /// Fills `hessian` and `gradient` with the normal equations `H δ = −g` of the problem
    /// re-weighted at the current poses (`g` is half the cost gradient).
    fn build_normal_equations(&mut self, c: f64) {
        self.hessian.fill(0.0);
        self.gradient.fill(0.0);
        for (f, &value) in self.factors.iter().zip(&self.s2) {
            let (r, j_from, j_to) = linearize(f, &self.poses);
            let weighted = f.information * cauchy(value, c).1;
            let wj_from = weighted * j_from;
            let wj_to = weighted * j_to;
            let wr = weighted * r;
            if let Some(v) = self.structure.variable[f.from] {
                add_rows(&mut self.gradient, v, &(j_from.transpose() * wr));
            }
            if let Some(v) = self.structure.variable[f.to] {
                add_rows(&mut self.gradient, v, &(j_to.transpose() * wr));
            }
            if let Some(block) = f.block_ff {
                block.add(&mut self.hessian, &(j_from.transpose() * wj_from));
            }
            if let Some(block) = f.block_tt {
                block.add(&mut self.hessian, &(j_to.transpose() * wj_to));
            }
            if let Some(block) = f.block_ft {
                block.add(&mut self.hessian, &(j_from.transpose() * wj_to));
            }
            if let Some(block) = f.block_tf {
                block.add(&mut self.hessian, &(j_to.transpose() * wj_from));
            }
        }
    }

    /// The step `δ = −(H + λD)⁻¹ g`, or `None` if the damped system cannot be factored.
    fn solve_damped(&mut self, scaling: &[f64]) -> Option<DVector<f64>> {
        self.damped.copy_from_slice(&self.hessian);
        for (k, block) in self.structure.diagonal.iter().enumerate() {
            for a in 0..6 {
                self.damped[block.start + a * block.stride + a] +=
                    self.damping * scaling[6 * k + a];
            }
        }
        let factored = match self.factorization.as_mut() {
            Some(existing) => existing.refactor(&self.damped).is_ok(),
            None => match CscCholesky::factor_numerical(self.symbolic.clone(), &self.damped) {
                Ok(fresh) => {
                    self.factorization = Some(fresh);
                    true
                }
                Err(_) => false,
            },
        };
        let step = match self.factorization.as_ref() {
            Some(cholesky) if factored => {
                let solution = cholesky.solve(&self.gradient);
                Some(-DVector::from_column_slice(solution.as_slice()))
            }
            _ => None,
        };
        match step {
            Some(step) if step.iter().all(|v| v.is_finite()) => Some(step),
            _ => {
                // A failed factorization leaves scratch values behind: start afresh next time.
                self.factorization = None;
                None
            }
        }
    }
}

/// Levenberg–Marquardt with graduated non-convexity over the nodes not `held`, from the poses
/// in `graph` (checked already, with each edge's information matrix in `informations`).
pub(super) fn solve(
    graph: &PoseGraph,
    held: &[bool],
    informations: Vec<Matrix6<f64>>,
    config: &OptimizeConfig,
) -> Result<(Vec<Pose>, OptimizeReport)> {
    let target_width = config.robust_kernel_width;
    let structure = build_structure(held, &graph.edges)?;
    let factors = prepare_factors(graph, &structure, informations);
    let mut s2 = Vec::with_capacity(factors.len());
    let initial_cost = evaluate(&factors, &graph.world_from_node, target_width, &mut s2);
    if !initial_cost.is_finite() || s2.iter().any(|v| !v.is_finite()) {
        return Err(Error::Invalid(format!(
            "pose graph: the initial cost is {initial_cost}; information entries or pose \
             offsets are too large to square (use metres and radians, covariances above ~1e-150)"
        )));
    }
    let hessian = vec![0.0; structure.pattern.nnz()];
    let mut solver = Solver {
        factors: &factors,
        structure: &structure,
        symbolic: CscSymbolicCholesky::factor(structure.pattern.clone()),
        factorization: None,
        damped: hessian.clone(),
        hessian,
        gradient: DVector::zeros(6 * structure.diagonal.len()),
        poses: graph.world_from_node.clone(),
        candidate: graph.world_from_node.clone(),
        candidate_s2: s2.clone(),
        s2,
        damping: config.initial_damping,
        nu: 2.0,
        exact_cost: EXACT_COST_PER_EDGE * factors.len() as f64,
    };

    // Graduated non-convexity: from a kernel wide enough to trust every edge of the input down
    // to the target width, each stage starting where the previous one ended.
    let widest = solver.s2.iter().fold(0.0_f64, |m, &v| m.max(v)).sqrt();
    let mut width = if config.graduated_kernel && widest > target_width {
        widest
    } else {
        target_width
    };
    let mut iterations = 0;
    let mut stages = 0;
    let converged = loop {
        let last = width <= target_width;
        let tolerance = if last {
            config.tolerance
        } else {
            config.tolerance.max(STAGE_TOLERANCE)
        };
        let (used, stage_converged) =
            solver.run(width, tolerance, config.max_iterations - iterations);
        iterations += used;
        stages += 1;
        if last || (!stage_converged && iterations >= config.max_iterations) {
            break stage_converged && last;
        }
        width = (width / GRADUATION_FACTOR).max(target_width);
    };

    let final_cost = solver.cost(target_width);
    let (edge_weights, edge_mahalanobis) = solver
        .s2
        .iter()
        .map(|&v| (cauchy(v, target_width).1, v.sqrt()))
        .unzip();
    Ok((
        solver.poses,
        OptimizeReport {
            iterations,
            initial_cost,
            final_cost,
            converged,
            edge_weights,
            edge_mahalanobis,
            kernel_stages: stages,
            final_damping: solver.damping,
        },
    ))
}
