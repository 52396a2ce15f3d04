//! Observables of the stress-controlled cell scene (002_89269f1b918188b3), one row of its
//! `series` table per sample: a port of `ShearCell.observe()` and `fabric()` in
//! `python/granflow/scenes/cell.py` (docs/columns.md, "Cell series"), with the same column
//! names, order and formulas.
//!
//! Conventions (as the Python): stresses are compressive-positive and so is the strain rate,
//! D = -sym L and W = -skew L; the L_ab columns stay kinematic (2.16).
//!
//! Round-off: the reductions the Python does with `np.sum` over a 3x3 array and `np.trace`
//! are done in numpy's order (pairwise summation over the 9 entries in C order; the diagonal
//! left to right), so they agree bit for bit given the same operands. Matrix products,
//! determinant, inverse and the 3x3 eigen-decomposition go through nalgebra rather than
//! BLAS/LAPACK, and the fabric sums over contacts run sequentially, so those agree with the
//! Python to round-off (relative to the matrices' norms), not bit for bit.
//!
//! Degenerate eigenvalues (measure-zero states): the eigenvectors of the 3x3 D then are not
//! unique and beta may differ from the Python's LAPACK choice, except for D a multiple of I
//! (where the two choices give the same |W : G|). For the 2x2 flow-plane blocks of theta_c the
//! LAPACK conventions of `np.linalg.eigh` are reproduced: an off-diagonal entry negligible by
//! dsteqr's test counts as zero, and a diagonal block then gives e_x when its xx entry is the
//! strictly larger, e_y otherwise (also for equal entries: 90 degrees).

use crate::error::{Error, Result};
use crate::{M3, V3};
use nalgebra::SymmetricEigen;

/// The inputs of one sample of the cell scene (kernel state plus the scene's constants).
pub struct CellInput<'a> {
    pub step: u64,
    pub t: f64,
    /// Cell matrix now (columns = cell vectors, upper-triangular).
    pub h: M3,
    /// Cell matrix at the start (F = H H0^-1).
    pub h0: M3,
    /// Velocity gradient L (kinematic, 2.16).
    pub l: M3,
    /// Contact stress (compressive positive).
    pub sigma_c: M3,
    /// Kinetic stress.
    pub sigma_k: M3,
    /// Total particle volume.
    pub vs: f64,
    /// Mean diameter.
    pub a: f64,
    pub density: f64,
    /// Particle count.
    pub n: usize,
    /// Contact pairs (particle indices < n, any consistent indexing).
    pub pairs: &'a [[u32; 2]],
    /// Branch vector r_ij = x_i - x_j of each pair (same length as `pairs`).
    pub branch: &'a [V3],
    pub max_overlap: f64,
    pub tilt_flips: f64,
}

/// The Python's `tiny`: guards of the ratios (beta, mu's, N's, I).
const TINY: f64 = 1e-300;

/// LAPACK's dlamch('E') (relative machine precision, 2^-53), used by dsteqr's deflation test.
const LAPACK_EPS: f64 = f64::EPSILON * 0.5;

const N_COLUMNS: usize = 86;

/// docs/columns.md "Cell series", in the order of `ShearCell.observe()`.
const COLUMNS: [&str; N_COLUMNS] = [
    "step",
    "t",
    // H (6)
    "H_xx",
    "H_xy",
    "H_xz",
    "H_yy",
    "H_yz",
    "H_zz",
    // F (9)
    "F_xx",
    "F_xy",
    "F_xz",
    "F_yx",
    "F_yy",
    "F_yz",
    "F_zx",
    "F_zy",
    "F_zz",
    // L (9)
    "L_xx",
    "L_xy",
    "L_xz",
    "L_yx",
    "L_yy",
    "L_yz",
    "L_zx",
    "L_zy",
    "L_zz",
    // D (6)
    "D_xx",
    "D_xy",
    "D_xz",
    "D_yy",
    "D_yz",
    "D_zz",
    // W (3) and scalars
    "W_xy",
    "W_xz",
    "W_yz",
    "shear_rate",
    "d1",
    "d2",
    "d3",
    "beta",
    "phi",
    "p",
    // sigma (9)
    "sigma_xx",
    "sigma_xy",
    "sigma_xz",
    "sigma_yx",
    "sigma_yy",
    "sigma_yz",
    "sigma_zx",
    "sigma_zy",
    "sigma_zz",
    // sigma_c (9)
    "sigma_c_xx",
    "sigma_c_xy",
    "sigma_c_xz",
    "sigma_c_yx",
    "sigma_c_yy",
    "sigma_c_yz",
    "sigma_c_zx",
    "sigma_c_zy",
    "sigma_c_zz",
    // sigma_k (9)
    "sigma_k_xx",
    "sigma_k_xy",
    "sigma_k_xz",
    "sigma_k_yx",
    "sigma_k_yy",
    "sigma_k_yz",
    "sigma_k_zx",
    "sigma_k_zy",
    "sigma_k_zz",
    // rheology
    "mu1",
    "mu2",
    "mu3",
    "I",
    "N0_tau",
    "N1_tau",
    // A (6)
    "A_xx",
    "A_xy",
    "A_xz",
    "A_yy",
    "A_yz",
    "A_zz",
    // structure and diagnostics
    "Z2",
    "theta_c",
    "n_contacts",
    "max_overlap",
    "tilt_flips",
];

/// The upper-triangular index pairs of the 6-component columns (xx xy xz yy yz zz).
const SYM6: [(usize, usize); 6] = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];

/// The column names in order (the same as [`cell_row`]'s), so a table can be laid out before
/// any sample.
pub fn cell_columns() -> Vec<&'static str> {
    COLUMNS.to_vec()
}

/// The row of the cell `series` table: (column name, value) in docs/columns.md order (exactly
/// the keys and order of `ShearCell.observe()`, "step" first). A non-finite value is an
/// [`Error::Instability`] naming the first such column.
pub fn cell_row(inp: &CellInput) -> Result<Vec<(&'static str, f64)>> {
    if inp.pairs.len() != inp.branch.len() {
        return Err(Error::Configuration {
            message: format!(
                "cell observables: {} contact pairs but {} branch vectors",
                inp.pairs.len(),
                inp.branch.len()
            ),
        });
    }
    let h = inp.h;
    let l = inp.l;
    let sc = inp.sigma_c;
    let sk = inp.sigma_k;
    let sig = sc + sk;
    let vol = h.determinant();
    let f = match inp.h0.try_inverse() {
        Some(h0_inv) => h * h0_inv,
        None => M3::from_element(f64::NAN),
    };
    let d = -0.5 * (l + l.transpose());
    let w = -0.5 * (l - l.transpose());
    let gd = (0.5 * np_sum(&d.component_mul(&d))).sqrt();
    let p = np_trace(&sig) / 3.0;
    let sp = 0.5 * (sig + sig.transpose());
    let (ev, d1h, d3h) = eigen_descending(&d);
    let g = d3h * d1h.transpose() - d1h * d3h.transpose();
    let beta = if gd > TINY {
        (np_sum(&w.component_mul(&g)) / (gd * np_sum(&g.component_mul(&g)))).abs()
    } else {
        0.0
    };
    // 002 (4.1), eta1 |D| + kappa1 = sigma:D / (2|D|), takes tr D = 0 (§2.1: I and D are
    // then orthogonal and p I drops out). Under the barostat tr D (= d ln phi/dt) is zero only
    // in the mean, and sigma:D as printed adds p tr D / (2|D|) to every sample: the same mean,
    // but a breathing term with a bounded integral that blocking cannot see as such (mu1's SE
    // came out twice its seed-to-seed spread: benchmarks/NOTES.md, "mu1, mu2 and the breathing").
    // The deviatoric projection (sigma - pI):D is (2.4)'s eta1/kappa1 part for any tr D; mu2
    // (below), N0 and N1 (5.3, 5.4) share it.
    let sdev = sp - M3::from_diagonal_element(p);
    let s_d = np_sum(&sdev.component_mul(&d));
    // (2.4)'s second-order tensor of the isochoric D: built from D's deviatoric part, for the
    // reason above (D^2 of a breathing D carries 2 tr(D)/3 D_dev, the same kind of term)
    let ddev = d - M3::from_diagonal_element(np_trace(&d) / 3.0);
    let dd = ddev * ddev;
    let d2 = dd - M3::from_diagonal_element(np_trace(&dd) / 3.0);
    let dw = d * w - w * d;
    let ok = gd > TINY && p > TINY && s_d.abs() > TINY;
    let (mu1, mu2, mu3, n0, n1) = if ok {
        let s_d2 = np_sum(&sp.component_mul(&d2));
        let s_dw = np_sum(&sp.component_mul(&dw));
        (
            s_d / (2.0 * gd * p),
            1.5 * s_d2 / (gd * gd * p),
            s_dw / (8.0 * gd * gd * p),
            -3.0 * s_d2 / (gd * s_d),
            s_dw / (gd * s_d),
        )
    } else {
        (0.0, 0.0, 0.0, 0.0, 0.0)
    };
    let inertial = if p > TINY {
        gd * inp.a / (p / inp.density).sqrt()
    } else {
        0.0
    };
    // fabric (5.1), rattler-free coordination, misalignment in the flow plane
    let nc = inp.pairs.len();
    let mut fab = M3::zeros();
    let mut z2 = 0.0;
    let mut theta = 0.0;
    if nc > 0 {
        fab = fabric(inp.branch);
        z2 = rattler_free_coordination(inp.pairs, inp.n)?;
        if gd > TINY {
            // compressive directions of A and of D in the xy plane
            let diff = flow_plane_angle(&fab) - flow_plane_angle(&d);
            theta = py_mod(diff + 90.0, 180.0) - 90.0;
        }
    }

    let mut v: Vec<f64> = Vec::with_capacity(N_COLUMNS);
    v.push(inp.step as f64);
    v.push(inp.t);
    v.extend(SYM6.iter().map(|&ab| h[ab]));
    push_full(&mut v, &f);
    push_full(&mut v, &l);
    v.extend(SYM6.iter().map(|&ab| d[ab]));
    v.extend([
        w[(0, 1)],
        w[(0, 2)],
        w[(1, 2)],
        gd,
        ev[0],
        ev[1],
        ev[2],
        beta,
        inp.vs / vol,
        p,
    ]);
    push_full(&mut v, &sig);
    push_full(&mut v, &sc);
    push_full(&mut v, &sk);
    v.extend([mu1, mu2, mu3, inertial, n0, n1]);
    v.extend(SYM6.iter().map(|&ab| fab[ab]));
    v.extend([z2, theta, nc as f64, inp.max_overlap, inp.tilt_flips]);
    debug_assert_eq!(v.len(), N_COLUMNS);

    if let Some(k) = v.iter().position(|x| !x.is_finite()) {
        let name = COLUMNS[k];
        return Err(Error::Instability {
            step: inp.step,
            particles: vec![],
            message: format!("non-finite cell observable {name}"),
            cause: non_finite_cause(name).into(),
        });
    }
    Ok(COLUMNS.iter().copied().zip(v).collect())
}

/// The likely cause of a non-finite column, for the error message.
fn non_finite_cause(name: &str) -> &'static str {
    if name.starts_with("A_") || name == "theta_c" {
        "a contact's branch vector r_ij is zero or non-finite (coincident or non-finite particle \
         centres), so its contact normal is undefined"
    } else if name.starts_with("F_") {
        "the initial cell matrix H0 is singular, or H or H0 holds a non-finite entry"
    } else if name == "phi" {
        "the cell volume det H is zero (collapsed cell) or non-finite"
    } else {
        "the cell's state or stresses became non-finite (NaN/inf): the integration diverged \
         (a time step too large for the contact stiffness, or runaway dilation or collapse of \
         the cell under the imposed stress)"
    }
}

/// The 9 entries row by row (a then b), as the Python's `for a: for b:` loops.
fn push_full(v: &mut Vec<f64>, m: &M3) {
    for a in 0..3 {
        for b in 0..3 {
            v.push(m[(a, b)]);
        }
    }
}

/// `np.sum` of a C-ordered 3x3 array: numpy's pairwise summation, which for 9 elements is
/// ((x0 + x1) + (x2 + x3)) + ((x4 + x5) + (x6 + x7)), then + x8.
fn np_sum(m: &M3) -> f64 {
    let x = |i: usize| m[(i / 3, i % 3)];
    ((x(0) + x(1)) + (x(2) + x(3))) + ((x(4) + x(5)) + (x(6) + x(7))) + x(8)
}

/// `np.trace`: the diagonal summed left to right.
fn np_trace(m: &M3) -> f64 {
    (m[(0, 0)] + m[(1, 1)]) + m[(2, 2)]
}

/// Python's float `%`: the result has the sign of the modulus (a zero result is +0 for a
/// positive modulus).
fn py_mod(x: f64, m: f64) -> f64 {
    let r = x % m;
    if r == 0.0 {
        0.0_f64.copysign(m)
    } else if (r < 0.0) != (m < 0.0) {
        r + m
    } else {
        r
    }
}

/// Eigenvalues of the symmetric `d` sorted descending, with the eigenvectors of the largest
/// and of the smallest (NaN if `d` is not finite: the caller reports the non-finite column).
fn eigen_descending(d: &M3) -> ([f64; 3], V3, V3) {
    let nan = (
        [f64::NAN; 3],
        V3::from_element(f64::NAN),
        V3::from_element(f64::NAN),
    );
    if !d.iter().all(|x| x.is_finite()) {
        return nan; // (nalgebra's iteration need not stop on NaN)
    }
    let Some(e) = SymmetricEigen::try_new(*d, f64::EPSILON, 10_000) else {
        return nan;
    };
    let mut order = [0usize, 1, 2];
    // numpy: eigh's ascending values, then argsort(ev)[::-1]
    order.sort_by(|&i, &j| e.eigenvalues[j].total_cmp(&e.eigenvalues[i]));
    let ev = order.map(|i| e.eigenvalues[i]);
    (
        ev,
        e.eigenvectors.column(order[0]).into_owned(),
        e.eigenvectors.column(order[2]).into_owned(),
    )
}

/// Fabric tensor A of 002 (5.1) over the contact normals r_ij/|r_ij|: P(n) = (1 + A : n n)/(4 pi)
/// gives <n n> = I/3 + 2A/15, so A = 15/2 (<n n> - I/3), trace-free and symmetric (zero with
/// no contacts).
pub fn fabric(branch: &[V3]) -> M3 {
    if branch.is_empty() {
        return M3::zeros();
    }
    // sum of n n over contacts: xx xy xz yy yz zz
    let mut s = [0.0f64; 6];
    for r in branch {
        let norm = (r.x * r.x + r.y * r.y + r.z * r.z).sqrt();
        let (x, y, z) = (r.x / norm, r.y / norm, r.z / norm);
        s[0] += x * x;
        s[1] += x * y;
        s[2] += x * z;
        s[3] += y * y;
        s[4] += y * z;
        s[5] += z * z;
    }
    let m = branch.len() as f64;
    let third = 1.0 / 3.0;
    let mut a = M3::zeros();
    for (k, &(i, j)) in SYM6.iter().enumerate() {
        let iso = if i == j { third } else { 0.0 };
        let v = 7.5 * (s[k] / m - iso);
        a[(i, j)] = v;
        a[(j, i)] = v;
    }
    a
}

/// Coordination number without rattlers: particles with fewer than 2 contacts are removed,
/// with their contacts, until none is left (the 2-core of the contact graph: whatever the
/// order of removal, the same as the Python's pass-by-pass removal); Z2 = 2 (contacts left) /
/// (particles left), 0 if none is left. A particle's count is its number of pair entries (a
/// pair (i, i) counts twice, as `np.bincount` of the pairs does).
fn rattler_free_coordination(pairs: &[[u32; 2]], n: usize) -> Result<f64> {
    let mut z = vec![0u32; n];
    for &[i, j] in pairs {
        let (i, j) = (i as usize, j as usize);
        if i >= n || j >= n {
            return Err(Error::Configuration {
                message: format!(
                    "cell observables: contact pair ({i}, {j}) refers to a particle >= n = {n}"
                ),
            });
        }
        z[i] += 1;
        z[j] += 1;
    }
    let mut keep: Vec<bool> = z.iter().map(|&k| k >= 2).collect();
    let mut active = vec![true; pairs.len()];
    // Passes over the contacts: a contact with a removed end goes, its ends' counts drop, and
    // an end that falls below 2 is removed at once (so a cascade mostly finishes in one pass).
    // A pass that removes no contact leaves every kept particle with >= 2 active contacts.
    loop {
        let mut changed = false;
        for (act, &[i, j]) in active.iter_mut().zip(pairs) {
            let (i, j) = (i as usize, j as usize);
            if *act && !(keep[i] && keep[j]) {
                *act = false;
                changed = true;
                z[i] -= 1;
                z[j] -= 1;
                if z[i] < 2 {
                    keep[i] = false;
                }
                if z[j] < 2 {
                    keep[j] = false;
                }
            }
        }
        if !changed {
            break;
        }
    }
    let n_keep = keep.iter().filter(|&&k| k).count();
    let n_act = active.iter().filter(|&&a| a).count();
    Ok(if n_keep > 0 {
        (2 * n_act) as f64 / n_keep as f64
    } else {
        0.0
    })
}

/// The Python's `angle(m, largest=True)`: the direction of the eigenvector of the largest
/// eigenvalue of the xy block of the symmetric `m` (`np.linalg.eigh`, lower triangle), as
/// atan2(e_y, e_x) in degrees mod 180.
///
/// With a non-negligible off-diagonal entry the eigenvalues are distinct and the direction is
/// 0.5 atan2(2 m_yx, m_xx - m_yy). Otherwise LAPACK (dsteqr) treats the block as diagonal
/// (|m_yx| <= sqrt|m_xx| sqrt|m_yy| eps) and sorts the eigenvalues ascending, swapping only
/// when m_yy < m_xx: the largest's eigenvector is e_x if m_yy < m_xx, else e_y (90 degrees).
fn flow_plane_angle(m: &M3) -> f64 {
    let (a, b, c) = (m[(0, 0)], m[(1, 0)], m[(1, 1)]);
    let deg = if b == 0.0 || b.abs() <= a.abs().sqrt() * c.abs().sqrt() * LAPACK_EPS {
        if c < a {
            0.0
        } else {
            90.0
        }
    } else {
        (0.5 * (2.0 * b).atan2(a - c)).to_degrees()
    };
    py_mod(deg, 180.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    const AX: [&str; 3] = ["x", "y", "z"];

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol * (1.0 + a.abs().max(b.abs()))
    }

    fn get(row: &[(&'static str, f64)], name: &str) -> f64 {
        row.iter()
            .find(|(k, _)| *k == name)
            .unwrap_or_else(|| panic!("no column {name}"))
            .1
    }

    fn base<'a>(pairs: &'a [[u32; 2]], branch: &'a [V3], n: usize) -> CellInput<'a> {
        CellInput {
            step: 1230,
            t: 24.6,
            h: M3::new(10.0, 1.0, 0.5, 0.0, 10.0, -0.25, 0.0, 0.0, 10.0),
            h0: M3::from_diagonal_element(10.0),
            l: M3::zeros(),
            sigma_c: M3::zeros(),
            sigma_k: M3::zeros(),
            vs: 600.0,
            a: 1.0,
            density: 1.0,
            n,
            pairs,
            branch,
            max_overlap: 1e-3,
            tilt_flips: 2.0,
        }
    }

    /// The column names built the Python's way (loops over AX, the same groups in order).
    fn python_columns() -> Vec<String> {
        let mut c: Vec<String> = vec!["step".into(), "t".into()];
        for (a, b) in SYM6 {
            c.push(format!("H_{}{}", AX[a], AX[b]));
        }
        for name in ["F", "L"] {
            for a in AX {
                for b in AX {
                    c.push(format!("{name}_{a}{b}"));
                }
            }
        }
        for (a, b) in SYM6 {
            c.push(format!("D_{}{}", AX[a], AX[b]));
        }
        for s in [
            "W_xy",
            "W_xz",
            "W_yz",
            "shear_rate",
            "d1",
            "d2",
            "d3",
            "beta",
            "phi",
            "p",
        ] {
            c.push(s.into());
        }
        for name in ["sigma", "sigma_c", "sigma_k"] {
            for a in AX {
                for b in AX {
                    c.push(format!("{name}_{a}{b}"));
                }
            }
        }
        for s in ["mu1", "mu2", "mu3", "I", "N0_tau", "N1_tau"] {
            c.push(s.into());
        }
        for (a, b) in SYM6 {
            c.push(format!("A_{}{}", AX[a], AX[b]));
        }
        for s in ["Z2", "theta_c", "n_contacts", "max_overlap", "tilt_flips"] {
            c.push(s.into());
        }
        c
    }

    #[test]
    fn columns_match_python_order_and_docs() {
        let cols = cell_columns();
        assert_eq!(cols, python_columns());
        assert_eq!(cols.len(), 86);
        // group sizes of docs/columns.md "Cell series"
        let count = |pre: &str| cols.iter().filter(|c| c.starts_with(pre)).count();
        assert_eq!(count("H_"), 6);
        assert_eq!(count("F_"), 9);
        assert_eq!(count("L_"), 9);
        assert_eq!(count("D_"), 6);
        assert_eq!(count("W_"), 3);
        assert_eq!(count("sigma_c_"), 9);
        assert_eq!(count("sigma_k_"), 9);
        assert_eq!(count("sigma_"), 27);
        assert_eq!(count("A_"), 6);
        // every column is named in the docs' cell section (a tensor by its group, e.g. "F_ab")
        let docs = include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/columns.md"));
        let sec = &docs[docs.find("## Cell").expect("cell section")..];
        let sec = &sec[..sec[3..].find("\n## ").map_or(sec.len(), |k| k + 3)];
        let groups = [
            "H_", "F_", "L_", "D_", "sigma_c_", "sigma_k_", "sigma_", "A_",
        ];
        for c in &cols {
            let want = match groups.iter().find(|g| c.starts_with(*g)) {
                Some(g) => format!("{g}ab"),
                None => c.to_string(),
            };
            assert!(
                sec.contains(&want),
                "{want} not in docs/columns.md cell section"
            );
        }
        // and the row carries the same names in the same order
        let row = cell_row(&base(&[], &[], 10)).unwrap();
        let names: Vec<&str> = row.iter().map(|(k, _)| *k).collect();
        assert_eq!(names, cols);
        assert_eq!(get(&row, "step"), 1230.0);
        assert_eq!(get(&row, "tilt_flips"), 2.0);
        assert_eq!(get(&row, "n_contacts"), 0.0);
        // phi = vs / det H; F = H H0^-1
        assert!(close(get(&row, "phi"), 600.0 / 1000.0, 1e-14));
        assert!(close(get(&row, "F_xy"), 0.1, 1e-14));
        assert!(close(get(&row, "F_yz"), -0.025, 1e-14));
        assert_eq!(get(&row, "H_xz"), 0.5);
    }

    /// Simple shear L = g e_x e_y (v_x = g y), so D = -sym L: D_xy = -g/2, W_xy = -g/2.
    /// shear_rate = sqrt(D:D/2) = g/2, eigenvalues +g/2, 0, -g/2, and beta = 1 (d1 = (1,-1)/√2,
    /// d3 = (1,1)/√2, G = d3 d1 - d1 d3 has G_xy = -1, G_yx = 1, W:G = g, G:G = 2).
    ///
    /// Stress sigma = diag(p + sx, p + sy, p + sz) + s (e_x e_y + e_y e_x), sx + sy + sz = 0,
    /// with s = -tau (002's compressive-positive imposed stress p I - tau(e_x e_y + e_y e_x),
    /// tau > 0 driving L_xy > 0). From the formulas:
    /// sp:D = 2 s D_xy = tau g, so mu1 = tau g / (2 (g/2) p) = tau/p (> 0 for tau, g > 0);
    /// D2 = diag(g²/12, g²/12, -g²/6), sp:D2 = -sz g²/4, mu2 = -1.5 sz/p, N0/tau = 1.5 sz/tau;
    /// DW = diag(-g²/2, g²/2, 0), sp:DW = (sy - sx) g²/2, mu3 = (sy - sx)/(4p),
    /// N1/tau = (sy - sx)/tau; so 002's mu2 = -N0/p and N1/tau = 4 mu3/mu1 hold.
    fn shear_input(g: f64, p: f64, tau: f64, sx: f64, sy: f64) -> (M3, M3) {
        let l = M3::new(0.0, g, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        let sz = -sx - sy;
        let mut s = M3::from_diagonal(&V3::new(p + sx, p + sy, p + sz));
        s[(0, 1)] = -tau;
        s[(1, 0)] = -tau;
        (l, s)
    }

    #[test]
    fn simple_shear_isotropic_stress() {
        let g = 0.02;
        let p = 3e-4;
        let (l, s) = shear_input(g, p, 0.0, 0.0, 0.0);
        let mut inp = base(&[], &[], 10);
        inp.l = l;
        // split the stress between the contact and kinetic parts
        inp.sigma_c = 0.75 * s;
        inp.sigma_k = s - inp.sigma_c;
        let row = cell_row(&inp).unwrap();
        assert!(close(get(&row, "shear_rate"), g / 2.0, 1e-14));
        assert!(close(get(&row, "d1"), g / 2.0, 1e-13));
        assert!(get(&row, "d2").abs() < 1e-15);
        assert!(close(get(&row, "d3"), -g / 2.0, 1e-13));
        assert!(close(get(&row, "beta"), 1.0, 1e-12));
        assert!(close(get(&row, "p"), p, 1e-14));
        assert_eq!(get(&row, "D_xy"), -g / 2.0);
        assert_eq!(get(&row, "W_xy"), -g / 2.0);
        assert_eq!(get(&row, "D_xx"), 0.0);
        // isotropic stress: sp:D = 0, so the `ok` guard sets all ratios to 0
        for k in ["mu1", "mu2", "mu3", "N0_tau", "N1_tau"] {
            assert_eq!(get(&row, k), 0.0, "{k}");
        }
        // I = gd a / sqrt(p / density)
        assert!(close(get(&row, "I"), (g / 2.0) / p.sqrt(), 1e-14));
        // no contacts: no fabric, Z2 = theta_c = 0
        for k in ["A_xx", "A_xy", "Z2", "theta_c"] {
            assert_eq!(get(&row, k), 0.0, "{k}");
        }
    }

    #[test]
    fn simple_shear_with_shear_stress_sign_convention() {
        let (g, p, tau, sx, sy) = (0.01, 2e-4, 0.5e-4, 0.2e-4, -0.05e-4);
        let sz = -sx - sy;
        let (l, s) = shear_input(g, p, tau, sx, sy);
        let mut inp = base(&[], &[], 10);
        inp.l = l;
        inp.sigma_c = s;
        inp.density = 2.0;
        inp.a = 1.1;
        let row = cell_row(&inp).unwrap();
        let mu1 = get(&row, "mu1");
        assert!(mu1 > 0.0);
        assert!(close(mu1, tau / p, 1e-12), "mu1 {mu1}");
        assert!(close(get(&row, "mu2"), -1.5 * sz / p, 1e-12));
        assert!(close(get(&row, "N0_tau"), 1.5 * sz / tau, 1e-12));
        assert!(close(get(&row, "mu3"), (sy - sx) / (4.0 * p), 1e-12));
        assert!(close(get(&row, "N1_tau"), (sy - sx) / tau, 1e-12));
        // 002's relations
        assert!(close(get(&row, "mu2"), -get(&row, "N0_tau") * mu1, 1e-12));
        assert!(close(
            get(&row, "N1_tau"),
            4.0 * get(&row, "mu3") / mu1,
            1e-12
        ));
        assert!(close(
            get(&row, "I"),
            (g / 2.0) * 1.1 / (p / 2.0).sqrt(),
            1e-14
        ));
        // the opposite stress sign gives mu1 < 0
        inp.sigma_c = shear_input(g, p, -tau, sx, sy).1;
        assert!(get(&cell_row(&inp).unwrap(), "mu1") < 0.0);
        // an isotropic compaction added to L changes the eigenvalues, not beta's eigenvectors
        inp.l = l + M3::from_diagonal_element(-1e-3);
        let row = cell_row(&inp).unwrap();
        assert!(close(get(&row, "d2"), 1e-3, 1e-12));
        let gd: f64 = (0.5 * (2.0 * (g / 2.0) * (g / 2.0) + 3e-6)).sqrt();
        assert!(close(get(&row, "shear_rate"), gd, 1e-13));
        assert!(close(get(&row, "beta"), g / (2.0 * gd), 1e-12));
        // ... and leaves the shear stress (sigma - pI):D = -tau g (the stress of -tau): the
        // breathing's p tr D (3p 1e-3, more than tau g here) is the pressure's, not mu1's
        assert!(close(get(&row, "mu1"), -tau * g / (2.0 * gd * p), 1e-12));
        // likewise mu2: (2.4)'s D^2 term from D's deviatoric part, sp:D2 = -sz g^2/4 as before
        assert!(close(
            get(&row, "mu2"),
            -1.5 * sz * g * g / (4.0 * gd * gd * p),
            1e-12
        ));
    }

    #[test]
    fn fabric_of_isotropic_and_aligned_normals() {
        let iso: Vec<V3> = [V3::x(), V3::y(), V3::z()]
            .iter()
            .flat_map(|&e| [2.0 * e, -0.5 * e])
            .collect();
        let a = fabric(&iso);
        assert!(a.iter().all(|x| x.abs() < 1e-15), "{a}");
        let along_x = [V3::x(), -3.0 * V3::x(), 0.7 * V3::x()];
        let a = fabric(&along_x);
        let want = 7.5 * M3::from_diagonal(&V3::new(2.0 / 3.0, -1.0 / 3.0, -1.0 / 3.0));
        assert!((a - want).abs().max() < 1e-14, "{a}");
        assert!(close(a[(0, 0)], 5.0, 1e-15));
        assert!(fabric(&[]).iter().all(|&x| x == 0.0));
        // trace-free and symmetric for any normals
        let some = [V3::new(1.0, 2.0, 3.0), V3::new(-0.3, 0.1, 0.9)];
        let a = fabric(&some);
        assert!(a.trace().abs() < 1e-14);
        assert_eq!(a, a.transpose());
    }

    /// The Python's loop as written (simultaneous removal per pass, recount by bincount).
    fn z2_python(pairs: &[[u32; 2]], n: usize) -> f64 {
        let bincount = |act: &[bool]| {
            let mut z = vec![0usize; n];
            for (k, &[i, j]) in pairs.iter().enumerate() {
                if act[k] {
                    z[i as usize] += 1;
                    z[j as usize] += 1;
                }
            }
            z
        };
        let mut act = vec![true; pairs.len()];
        let mut keep = vec![true; n];
        let mut z = bincount(&act);
        loop {
            let bad: Vec<bool> = (0..n).map(|v| keep[v] && z[v] < 2).collect();
            if !bad.iter().any(|&b| b) {
                break;
            }
            for v in 0..n {
                keep[v] &= !bad[v];
            }
            for (k, &[i, j]) in pairs.iter().enumerate() {
                act[k] &= keep[i as usize] && keep[j as usize];
            }
            z = bincount(&act);
        }
        let nk = keep.iter().filter(|&&k| k).count();
        let na = act.iter().filter(|&&a| a).count();
        if nk > 0 {
            2.0 * na as f64 / nk as f64
        } else {
            0.0
        }
    }

    #[test]
    fn z2_removes_rattlers_iteratively() {
        // triangle 0-1-2, particle 3 with one contact, particle 4 isolated
        let tri = [[0, 1], [1, 2], [2, 0], [3, 0]];
        assert_eq!(rattler_free_coordination(&tri, 5).unwrap(), 2.0);
        // triangle plus the chain 0-3-4-5: removing 5 exposes 4, then 3
        let chain = [[0, 1], [1, 2], [2, 0], [0, 3], [3, 4], [4, 5]];
        assert_eq!(rattler_free_coordination(&chain, 6).unwrap(), 2.0);
        // the chain listed leaf-last, so that the cascade runs against the pass order
        let chain_rev = [[4, 5], [3, 4], [0, 3], [0, 1], [1, 2], [2, 0]];
        assert_eq!(rattler_free_coordination(&chain_rev, 6).unwrap(), 2.0);
        // two triangles joined by a bridge: nobody is a rattler, Z2 = 2 * 7 / 6
        let two = [[0, 1], [1, 2], [2, 0], [3, 4], [4, 5], [5, 3], [2, 3]];
        assert_eq!(rattler_free_coordination(&two, 6).unwrap(), 14.0 / 6.0);
        // a lone pair and an open chain: everything goes, Z2 = 0
        assert_eq!(rattler_free_coordination(&[[0, 1]], 2).unwrap(), 0.0);
        assert_eq!(
            rattler_free_coordination(&[[0, 1], [1, 2], [2, 3]], 4).unwrap(),
            0.0
        );
        // a double contact keeps both particles (count 2 each), as bincount counts it
        assert_eq!(
            rattler_free_coordination(&[[0, 1], [1, 0]], 3).unwrap(),
            2.0
        );
        // an index out of range is an error
        assert!(rattler_free_coordination(&[[0, 5]], 5).is_err());
        // random sparse graphs: the same as the Python's pass-by-pass removal
        let mut s: u64 = 0x9e37_79b9_7f4a_7c15;
        let mut next = |m: u64| {
            s = s
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (s >> 33) % m
        };
        for trial in 0..200 {
            let n = 5 + next(60) as usize;
            let m = next(2 * n as u64) as usize;
            let pairs: Vec<[u32; 2]> = (0..m)
                .map(|_| [next(n as u64) as u32, next(n as u64) as u32])
                .collect();
            assert_eq!(
                rattler_free_coordination(&pairs, n).unwrap(),
                z2_python(&pairs, n),
                "trial {trial}"
            );
        }
    }

    #[test]
    fn theta_c_between_fabric_and_strain_rate() {
        // simple shear: the compressive direction of D (largest eigenvalue) is at 135 degrees
        let g = 0.02;
        let (l, s) = shear_input(g, 1e-4, 0.5e-4, 0.0, 0.0);
        let mut d = -0.5 * (l + l.transpose());
        assert!(close(flow_plane_angle(&d), 135.0, 1e-12));
        let pairs = [[0u32, 1], [1, 2], [2, 0]];
        for (phi, want) in [
            (145.0, 10.0),
            (235.0, -80.0),
            (230.0, -85.0),
            (100.0, -35.0),
        ] {
            let r: f64 = f64::to_radians(phi);
            let n = V3::new(r.cos(), r.sin(), 0.0);
            let branch = [n, -2.0 * n, 0.5 * n];
            let mut inp = base(&pairs, &branch, 3);
            inp.l = l;
            inp.sigma_c = s;
            let row = cell_row(&inp).unwrap();
            assert!(
                close(get(&row, "theta_c"), want, 1e-11),
                "phi {phi}: {}",
                get(&row, "theta_c")
            );
            assert_eq!(get(&row, "Z2"), 2.0);
            assert_eq!(get(&row, "n_contacts"), 3.0);
        }
        // LAPACK's conventions for a diagonal (or negligibly off-diagonal) block
        d = M3::from_diagonal(&V3::new(2.0, 1.0, 0.0));
        assert_eq!(flow_plane_angle(&d), 0.0);
        d = M3::from_diagonal(&V3::new(1.0, 2.0, 0.0));
        assert_eq!(flow_plane_angle(&d), 90.0);
        d = M3::from_diagonal(&V3::new(1.0, 1.0, 5.0));
        assert_eq!(flow_plane_angle(&d), 90.0);
        d[(0, 1)] = 1e-300;
        d[(1, 0)] = 1e-300;
        assert_eq!(flow_plane_angle(&d), 90.0);
        d[(0, 1)] = 0.25;
        d[(1, 0)] = 0.25;
        assert!(close(flow_plane_angle(&d), 45.0, 1e-13));
        assert_eq!(flow_plane_angle(&M3::zeros()), 90.0);
        // Python's modulo
        assert_eq!(py_mod(-1e-17, 180.0), 180.0);
        assert_eq!(py_mod(-180.0, 180.0), 0.0);
        assert!(py_mod(-180.0, 180.0).is_sign_positive());
        assert_eq!(py_mod(-80.0, 180.0), 100.0);
        assert_eq!(py_mod(370.0, 180.0), 10.0);
    }

    #[test]
    fn non_finite_input_names_the_column() {
        let mut inp = base(&[], &[], 10);
        inp.l[(0, 0)] = f64::NAN; // also: the eigen-decomposition must not hang on NaN
        match cell_row(&inp) {
            Err(Error::Instability {
                step,
                message,
                cause,
                ..
            }) => {
                assert_eq!(step, 1230);
                assert_eq!(message, "non-finite cell observable L_xx");
                assert!(!cause.is_empty());
            }
            other => panic!("{other:?}"),
        }
        let mut inp = base(&[], &[], 10);
        inp.sigma_k[(2, 1)] = f64::INFINITY;
        let e = cell_row(&inp).unwrap_err();
        assert!(e.to_string().contains("sigma_zy"), "{e}");
        // a zero branch vector: undefined normal, reported at the fabric
        let pairs = [[0u32, 1]];
        let branch = [V3::zeros()];
        let e = cell_row(&base(&pairs, &branch, 2)).unwrap_err();
        assert!(e.to_string().contains("observable A_xx"), "{e}");
        // a singular H0
        let mut inp = base(&[], &[], 10);
        inp.h0 = M3::zeros();
        let e = cell_row(&inp).unwrap_err();
        assert!(e.to_string().contains("observable F_xx"), "{e}");
        // mismatched lengths
        assert!(cell_row(&base(&pairs, &[], 2)).is_err());
    }
}
