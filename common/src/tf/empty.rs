//! Opacity summed-area table: "is τ identically 0 on [min, max]?" answered with
//! integer arithmetic, for skipping empty space (e.g. bricks whose value range
//! maps to τ = 0 under the current transfer function).

use anyhow::Result;

use super::function::TransferFunction;
use super::preint::{check_range, node_position};

/// Prefix counts of "τ is non-zero somewhere in this bin" over the bins of a
/// data range [vmin, vmax] (the same bins as a [`super::PreintTable`] built
/// with the same arguments).
///
/// A bin [s_j, s_{j+1}] counts when τ > 0 at either node, or a control point
/// with τ > 0 lies in the closed bin. τ is piecewise linear and ≥ 0, so a bin
/// that does not count has τ ≡ 0 on it: the answer of [`Self::is_empty`] is
/// exact at bin granularity and conservative (it never says empty when τ > 0
/// anywhere on the queried range). Beyond the table range each side is one
/// flag: τ > 0 anywhere on (−∞, vmin], resp. [vmax, ∞), under the transfer
/// function itself (which is constant only beyond its own first and last
/// point).
#[derive(Clone, Debug)]
pub struct EmptinessTable {
    vmin: f64,
    vmax: f64,
    dx: f64,
    n_bins: usize,
    /// `prefix[j]` = number of non-empty bins among bins 0..j (N+1 entries).
    prefix: Vec<u32>,
    below_nonzero: bool,
    above_nonzero: bool,
}

impl EmptinessTable {
    /// Builds the table of `tf` over [vmin, vmax] with `n_bins` bins (same
    /// rules as [`super::PreintTable::new`]).
    pub fn new(tf: &TransferFunction, vmin: f64, vmax: f64, n_bins: usize) -> Result<Self> {
        let (vmin, vmax, dx) = check_range(vmin, vmax, n_bins)?;
        // Values of the control points with τ > 0, sorted.
        let positive: Vec<f64> = tf
            .points()
            .iter()
            .filter(|p| p.extinction > 0.0)
            .map(|p| p.value)
            .collect();
        let node = |i: usize| node_position(vmin, vmax, dx, n_bins, i);
        let mut prefix = Vec::with_capacity(n_bins + 1);
        prefix.push(0u32);
        let mut count = 0u32;
        let mut tau_left = tf.tau(node(0));
        for j in 0..n_bins {
            let (x0, x1) = (node(j), node(j + 1));
            let tau_right = tf.tau(x1);
            let k = positive.partition_point(|&v| v < x0);
            let point_inside = k < positive.len() && positive[k] <= x1;
            if tau_left > 0.0 || tau_right > 0.0 || point_inside {
                count += 1;
            }
            prefix.push(count);
            tau_left = tau_right;
        }
        let below_nonzero = tf.tau(vmin) > 0.0 || positive.first().is_some_and(|&v| v <= vmin);
        let above_nonzero = tf.tau(vmax) > 0.0 || positive.last().is_some_and(|&v| v >= vmax);
        Ok(EmptinessTable {
            vmin,
            vmax,
            dx,
            n_bins,
            prefix,
            below_nonzero,
            above_nonzero,
        })
    }

    fn node(&self, i: usize) -> f64 {
        node_position(self.vmin, self.vmax, self.dx, self.n_bins, i)
    }

    /// For s in [vmin, vmax]: the bin j with s_j ≤ s < s_{j+1} (the last bin
    /// for s = vmax), decided by the same node positions the table was built
    /// on. With `upper`, the bin with s_j < s ≤ s_{j+1} instead (bin 0 for
    /// s = vmin): a range ending exactly on a node needs no bin beyond it,
    /// since the node's τ is part of the bin on its left.
    fn bin_of(&self, s: f64, upper: bool) -> usize {
        let last = self.n_bins - 1;
        let mut j = (((s - self.vmin) / self.dx).max(0.0) as usize).min(last);
        let below = |x: f64| if upper { s <= x } else { s < x };
        while j > 0 && below(self.node(j)) {
            j -= 1;
        }
        while j < last && !below(self.node(j + 1)) {
            j += 1;
        }
        j
    }

    /// True when τ is identically 0 on [min, max] (bounds in either order);
    /// conservative: never true when τ > 0 anywhere on the range. A NaN bound
    /// gives false.
    pub fn is_empty(&self, min: f64, max: f64) -> bool {
        if min.is_nan() || max.is_nan() {
            return false;
        }
        let (min, max) = if min <= max { (min, max) } else { (max, min) };
        if min < self.vmin && self.below_nonzero {
            return false;
        }
        if max > self.vmax && self.above_nonzero {
            return false;
        }
        let (lo, hi) = (min.max(self.vmin), max.min(self.vmax));
        if lo > hi {
            // Entirely on one side of the table, and that side is empty.
            return true;
        }
        let jlo = self.bin_of(lo, false);
        let jhi = self.bin_of(hi, true).max(jlo);
        self.prefix[jhi + 1] == self.prefix[jlo]
    }

    /// The prefix counts (N+1 entries; entry j = non-empty bins among 0..j),
    /// e.g. for a GPU copy of the table.
    pub fn prefix_counts(&self) -> &[u32] {
        &self.prefix
    }

    pub fn n_bins(&self) -> usize {
        self.n_bins
    }
}
