//! The `gemm` crate's f32 product on strided matrix views (the one place its nineteen arguments
//! are spelled out), and the output pointer that parallel tasks writing disjoint parts share.

/// A matrix in memory: its first element and the strides (in elements) between its rows and
/// between its columns.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Strided<P> {
    pub ptr: P,
    pub row_stride: isize,
    pub col_stride: isize,
}

impl<P> Strided<P> {
    /// Rows `row_stride` apart, columns contiguous.
    pub fn rows(ptr: P, row_stride: usize) -> Self {
        Strided {
            ptr,
            row_stride: row_stride as isize,
            col_stride: 1,
        }
    }

    /// Columns `col_stride` apart, rows contiguous (a transposed row-major matrix).
    pub fn columns(ptr: P, col_stride: usize) -> Self {
        Strided {
            ptr,
            row_stride: 1,
            col_stride: col_stride as isize,
        }
    }
}

/// `dst = scale · lhs · rhs` (`[m, k] × [k, n]`), or `dst += …` when `accumulate`.
///
/// # Safety
/// Each view addresses only memory of its matrix (`dst`: `m × n`, `lhs`: `m × k`, `rhs`:
/// `k × n`) that is valid for the access, and `dst` overlaps neither input.
#[allow(clippy::too_many_arguments)] // a GEMM's shape and operands
pub(crate) unsafe fn gemm_f32(
    [m, n, k]: [usize; 3],
    dst: Strided<*mut f32>,
    lhs: Strided<*const f32>,
    rhs: Strided<*const f32>,
    accumulate: bool,
    scale: f32,
    parallelism: gemm::Parallelism,
) {
    gemm::gemm(
        m,
        n,
        k,
        dst.ptr,
        dst.col_stride,
        dst.row_stride,
        accumulate,
        lhs.ptr,
        lhs.col_stride,
        lhs.row_stride,
        rhs.ptr,
        rhs.col_stride,
        rhs.row_stride,
        if accumulate { 1.0 } else { 0.0 },
        scale,
        false,
        false,
        false,
        parallelism,
    );
}

/// An output pointer shared by parallel tasks, each writing its own disjoint part of it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SharedOut(*mut f32);

// SAFETY: the tasks sharing it write disjoint elements (each user states which).
unsafe impl Send for SharedOut {}
unsafe impl Sync for SharedOut {}

impl SharedOut {
    pub fn new(out: &mut [f32]) -> Self {
        SharedOut(out.as_mut_ptr())
    }

    /// The pointer `offset` elements in (a method, so that closures capture the whole value).
    ///
    /// # Safety
    /// `offset` is inside the output.
    pub unsafe fn at(self, offset: usize) -> *mut f32 {
        self.0.add(offset)
    }
}
