//! A packed im2col for 8-bit convolutions that writes the matrix kernel's panels directly.
//!
//! tract 0.23 lowers every quantized convolution to `Im2col` + `OptMatMul`. Its `Im2col` feeds
//! the packing writer one element at a time in K-outer order; for the K=4-inner layout of the
//! VNNI/AMX int8 kernels (`PackedI8K4`) every element lands 4 bytes from the previous one, and
//! on the paper-size milliEgo graph that op costs about as much as all the int8 matrix products
//! together (docs/int8-speed.md). [`PackedIm2Col`] produces the same bytes in three cheap passes:
//!
//! 1. pad the input once and split every row into its `stride_x` phases, so that each patch row
//!    (one input channel, one kernel tap, all output positions) is a run of contiguous copies;
//! 2. for each K=4 block and output row, interleave the 4 taps' contiguous runs straight into
//!    the panels (`PackedI8K4`); for `PackedFormat` (K-major), copy each run into its panel.
//!
//! The output is the value tract's `Im2col` produces (a `PackedMatrixStorage` of
//! `EagerPackedInput`s, one per batch item and group), byte for byte, so the matrix product
//! after it is unchanged; `tests/bit_exact.rs` checks that on many geometries.

use std::sync::Arc;
use tract_onnx::prelude::*;
use tract_onnx::tract_core::internal::*;
use tract_onnx::tract_core::ops::cnn::conv::Im2Col;
use tract_onnx::tract_core::ops::nn::DataFormat;
use tract_onnx::tract_core::tract_linalg::mmm::{
    EagerPackedInput, MMMInputFormat, MMMInputValue, PackedExoticFact, PackedMatrixStorage,
};
use tract_onnx::tract_core::tract_linalg::pack::{PackedFormat, PackedI8K4};
use tract_onnx::tract_core::{as_op, op_as_typed_op, op_out_of_plan};

/// Packed buffers start on a cache line (the kernels ask for 16 bytes): tile loads of 64-byte
/// panel rows then never straddle two lines.
const CACHE_LINE: usize = 64;

/// Where one patch element goes in a panel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Layout {
    /// `PackedI8K4`: byte `(k/4)*4r + e*4 + k%4` of the panel holds (k, e).
    K4,
    /// `PackedFormat`: byte `k*r + e` of the panel holds (k, e).
    KMajor,
}

/// The convolution's geometry, resolved once for the plan's concrete input shape.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
struct Geometry {
    /// Batch items (1 when the data format has no N axis).
    batch: usize,
    /// Input channels, height, width.
    c: usize,
    h: usize,
    w: usize,
    group: usize,
    /// Input channels per group.
    cpg: usize,
    kh: usize,
    kw: usize,
    /// Strides and dilations (y, x).
    sy: usize,
    sx: usize,
    dy: usize,
    dx: usize,
    /// Padding before (top, left).
    pt: usize,
    pl: usize,
    /// Output height and width.
    ho: usize,
    wo: usize,
    /// Rows of the padded input, and the length of one x phase of a padded row.
    hp: usize,
    wq: usize,
    /// Patch length (`cpg * kh * kw`) and patch count (`ho * wo`).
    k: usize,
    n: usize,
}

/// A run of output positions that are contiguous in one output row and in one panel.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
struct Run {
    /// Byte offset of the panel in the packed buffer.
    panel: usize,
    /// First item of the run within the panel.
    item: usize,
    /// Offset of the run's first tap in the padded input, relative to the tap's origin.
    src: usize,
    len: usize,
}

/// tract's eager `Im2col` for 8-bit inputs, rewritten to write panels row-block by row-block.
/// Built from a node of the optimised plan by [`PackedIm2Col::from_tract`].
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct PackedIm2Col {
    geo: Geometry,
    layout: Layout,
    /// Panel width (patches per panel).
    r: usize,
    /// Bytes per panel, and the buffer alignment the kernel expects.
    panel_len: usize,
    align: usize,
    format: Box<dyn MMMInputFormat>,
    dt: DatumType,
    /// Every output row cut at panel boundaries, in output order.
    runs: Vec<Run>,
    /// [`PackedIm2Col::tap`] of every patch row, k rounded up to 4 with [`NO_TAP`].
    taps: Vec<usize>,
}

/// Bytes that tract's AMX int8 kernels read past the end of a K=4-inner B panel of `r` columns
/// and depth `k` \[B\].
///
/// `avx512amx_mmm_i32_{8x8,16x16}` load B as whole 16-row tiles of `4 r` bytes, i.e. 64 K values
/// per `tileloadd`, `ceil(k / 64)` times per panel, while `PackedI8K4` pads a panel only to a
/// multiple of 4 in K. The last tile of the last panel therefore reaches
/// `(ceil(k/64)*64 - ceil(k/4)*4) * r` bytes past the buffer: a segfault when that crosses into an
/// unmapped page (docs/amx-overread.md). The bytes read there meet the zero K-padding of the A
/// panel, so they never change a result; allocating them (zeroed) makes the read safe.
pub fn amx_tile_slack(k: usize, r: usize) -> usize {
    (k.div_ceil(64) * 64 - k.div_ceil(4) * 4) * r
}

/// A patch row past k (K=4 padding): zeros.
const NO_TAP: usize = usize::MAX;

impl PackedIm2Col {
    /// The replacement for `op` (an `Im2col` node whose input fact is `input` and whose output
    /// fact is `output`), or why it cannot take that node's place (tract's op then stays).
    pub fn from_tract(
        op: &Im2Col,
        input: &TypedFact,
        output: &TypedFact,
    ) -> Result<PackedIm2Col, String> {
        let dt = input.datum_type;
        if dt.size_of() != 1 {
            return Err(format!("input is {dt:?}, only 8-bit inputs are handled"));
        }
        let shape = input
            .shape
            .as_concrete()
            .ok_or_else(|| format!("input shape {:?} is not concrete", input.shape))?;
        let spec = &op.pool_spec;
        let (batch, c, h, w) = match (spec.data_format, shape) {
            (DataFormat::NCHW, &[n, c, h, w]) => (n, c, h, w),
            (DataFormat::CHW, &[c, h, w]) => (1, c, h, w),
            (f, s) => return Err(format!("layout {f:?} with shape {s:?} (only 2-D NCHW/CHW)")),
        };
        let &[kh, kw] = &spec.kernel_shape[..] else {
            return Err(format!("kernel {:?} is not 2-D", spec.kernel_shape));
        };
        let (strides, dilations) = (spec.strides(), spec.dilations());
        let (sy, sx, dy, dx) = (strides[0], strides[1], dilations[0], dilations[1]);
        if [kh, kw, sy, sx, dy, dx].contains(&0) {
            return Err("zero kernel, stride or dilation".into());
        }
        let group = op.group;
        if group == 0 || c % group != 0 || c != spec.input_channels {
            return Err(format!("{c} input channels in {group} groups"));
        }
        let pads = spec.computed_padding(&[h, w]);
        let (pt, pb, ho) = (pads[0].pad_before, pads[0].pad_after, pads[0].convoluted);
        let (pl, pr, wo) = (pads[1].pad_before, pads[1].pad_after, pads[1].convoluted);
        let (k, n) = (c / group * kh * kw, ho * wo);
        if n == 0 {
            return Err("empty output".into());
        }
        // The padded input must hold every tap of every output position.
        let hp = (h + pt + pb).max((ho - 1) * sy + (kh - 1) * dy + 1);
        let wp = (w + pl + pr).max((wo - 1) * sx + (kw - 1) * dx + 1);
        let pof = output
            .exotic_fact
            .as_ref()
            .and_then(|f| f.downcast_ref::<PackedExoticFact>())
            .ok_or("output is not a packed matrix")?;
        if pof.k != k || pof.mn.as_i64() != Some(n as i64) {
            return Err(format!(
                "packed fact k={} mn={} against k={k} n={n}",
                pof.k, pof.mn
            ));
        }
        let (layout, r, panel_len, align) = if let Some(f) = pof.format.downcast_ref::<PackedI8K4>()
        {
            (Layout::K4, f.r, f.single_panel_len(k), f.alignment())
        } else if let Some(f) = pof.format.downcast_ref::<PackedFormat>() {
            if f.dt.size_of() != 1 {
                return Err(format!("packing for {:?}", f.dt));
            }
            (Layout::KMajor, f.r, f.single_panel_len(k), f.alignment())
        } else {
            return Err(format!("packing {} is not handled", pof.format));
        };
        if r == 0 || panel_len < r * k {
            return Err(format!("panel of {panel_len} bytes for r={r} k={k}"));
        }
        let geo = Geometry {
            batch,
            c,
            h,
            w,
            group,
            cpg: c / group,
            kh,
            kw,
            sy,
            sx,
            dy,
            dx,
            pt,
            pl,
            ho,
            wo,
            hp,
            wq: wp.div_ceil(sx),
            k,
            n,
        };
        let row_step = sy * sx * geo.wq;
        let mut runs = Vec::new();
        for yo in 0..ho {
            let mut xo = 0;
            while xo < wo {
                let n = yo * wo + xo;
                let (p, item) = (n / r, n % r);
                let len = (r - item).min(wo - xo);
                runs.push(Run {
                    panel: p * panel_len,
                    item,
                    src: yo * row_step + xo,
                    len,
                });
                xo += len;
            }
        }
        let mut op = PackedIm2Col {
            geo,
            layout,
            r,
            panel_len,
            align,
            format: pof.format.clone(),
            dt,
            runs,
            taps: vec![],
        };
        op.taps = (0..k.div_ceil(4) * 4)
            .map(|kk| if kk < k { op.tap(kk) } else { NO_TAP })
            .collect();
        Ok(op)
    }

    /// Pads one group's channels into `pin` (`[cpg][hp][sx phases][wq]`, pad bytes around)
    /// so that tap (ky, kx) of output row yo is `wo` contiguous bytes.
    fn split(&self, src: &[u8], pin: &mut [u8]) {
        let g = &self.geo;
        for (ci, plane) in src.chunks_exact(g.h * g.w).enumerate() {
            for (y, row) in plane.chunks_exact(g.w).enumerate() {
                let base = (ci * g.hp + y + g.pt) * g.sx * g.wq;
                if g.sx == 1 {
                    pin[base + g.pl..][..g.w].copy_from_slice(row);
                } else if g.sx == 2 {
                    // Even and odd columns: one de-interleaving pass over the row.
                    let (ph0, ph1) = pin[base..base + 2 * g.wq].split_at_mut(g.wq);
                    let (first, second) = if g.pl.is_multiple_of(2) {
                        (ph0, ph1)
                    } else {
                        (ph1, ph0)
                    };
                    let (j0, j1) = (g.pl / 2, g.pl.div_ceil(2));
                    let (first, second) = (&mut first[j0..], &mut second[j1..]);
                    let blocks = row.chunks_exact(32);
                    let done = row.len() - blocks.remainder().len();
                    for (i, block) in blocks.enumerate() {
                        if let Ok(block) = <&[u8; 32]>::try_from(block) {
                            let (even, odd) = deinterleave32(block);
                            first[16 * i..16 * i + 16].copy_from_slice(&even);
                            second[16 * i..16 * i + 16].copy_from_slice(&odd);
                        }
                    }
                    for (x, &v) in row.iter().enumerate().skip(done) {
                        if x % 2 == 0 {
                            first[x / 2] = v;
                        } else {
                            second[x / 2] = v;
                        }
                    }
                } else {
                    // Phase `ph` holds padded columns ph, ph + sx, ...: a strided gather per phase.
                    for ph in 0..g.sx {
                        let xp0 = g.pl + (ph + g.sx - g.pl % g.sx) % g.sx;
                        if xp0 >= g.pl + g.w {
                            continue;
                        }
                        let dst = &mut pin[base + ph * g.wq + xp0 / g.sx..];
                        for (d, &v) in dst.iter_mut().zip(row[xp0 - g.pl..].iter().step_by(g.sx)) {
                            *d = v;
                        }
                    }
                }
            }
        }
    }

    /// Offset in `pin` of patch row `kk` (input channel, kernel tap) at output position (0, 0);
    /// output row `yo` adds `yo * sy * sx * wq`, column `xo` adds `xo`.
    fn tap(&self, kk: usize) -> usize {
        let g = &self.geo;
        let taps = g.kh * g.kw;
        let (ci, ky, kx) = (kk / taps, kk % taps / g.kw, kk % g.kw);
        let xoff = kx * g.dx;
        (ci * g.hp + ky * g.dy) * g.sx * g.wq + (xoff % g.sx) * g.wq + xoff / g.sx
    }

    /// One group of one batch item: the packed panels (`out` arrives zeroed, which is the
    /// padding past k and n).
    fn pack(&self, pin: &[u8], zeros: &[u8], out: &mut [u8]) {
        let r = self.r;
        // Run-major: every run fills its panel's rows in order, so the writes stream through
        // one panel at a time while the taps are read from the (cache-resident) padded input.
        match self.layout {
            Layout::K4 => {
                for run in &self.runs {
                    let dst = &mut out[run.panel..run.panel + self.panel_len];
                    for (kb, taps) in self.taps.chunks_exact(4).enumerate() {
                        let src = |j: usize| match taps[j] {
                            NO_TAP => &zeros[..run.len],
                            t => &pin[t + run.src..][..run.len],
                        };
                        interleave4(
                            &mut dst[kb * 4 * r + 4 * run.item..][..4 * run.len],
                            src(0),
                            src(1),
                            src(2),
                            src(3),
                        );
                    }
                }
            }
            Layout::KMajor => {
                for run in &self.runs {
                    let dst = &mut out[run.panel..run.panel + self.panel_len];
                    for (kk, &t) in self.taps.iter().take(self.geo.k).enumerate() {
                        dst[kk * r + run.item..][..run.len]
                            .copy_from_slice(&pin[t + run.src..][..run.len]);
                    }
                }
            }
        }
    }

    fn eval_bytes(&self, x: &[u8], pad: u8) -> TractResult<Tensor> {
        let g = &self.geo;
        let plane = g.h * g.w;
        ensure!(
            x.len() == g.batch * g.c * plane,
            "PackedIm2col: {} input bytes, expected {}",
            x.len(),
            g.batch * g.c * plane
        );
        let mut pin = vec![pad; g.cpg * g.hp * g.sx * g.wq];
        let zeros = vec![0u8; self.r];
        let panels = g.n.div_ceil(self.r);
        let mut values: TVec<Box<dyn MMMInputValue>> = TVec::with_capacity(g.batch * g.group);
        for b in 0..g.batch {
            for grp in 0..g.group {
                let src = &x[(b * g.c + grp * g.cpg) * plane..][..g.cpg * plane];
                self.split(src, &mut pin);
                // Zeroed slack past the last panel: the AMX kernels read whole K=64 tiles
                // (see [`amx_tile_slack`]).
                let mut packed = Tensor::zero_aligned_dt(
                    u8::datum_type(),
                    &[panels * self.panel_len + amx_tile_slack(g.k, self.r)],
                    self.align.max(CACHE_LINE),
                )?;
                self.pack(&pin, &zeros, packed.as_bytes_mut());
                values.push(Box::new(EagerPackedInput {
                    fact: PackedExoticFact {
                        format: self.format.clone(),
                        k: g.k,
                        mn: g.n.to_dim(),
                    },
                    packed: Arc::new(packed.into_blob()?),
                    panel_bytes: self.panel_len,
                    mn: g.n,
                }));
            }
        }
        Ok(PackedMatrixStorage::new_batched(&[g.batch, g.group], values).into_tensor(self.dt))
    }
}

/// `dst[4i..4i+4] = [a[i], b[i], c[i], d[i]]`: 16 items at a time through [`interleave16`], then
/// 8 through [`interleave8`] (the 8-wide panels), then one by one.
fn interleave4(dst: &mut [u8], a: &[u8], b: &[u8], c: &[u8], d: &[u8]) {
    if let (Ok(o), Ok(a), Ok(b), Ok(c), Ok(d)) = (
        <&mut [u8; 64]>::try_from(&mut *dst),
        <&[u8; 16]>::try_from(a),
        <&[u8; 16]>::try_from(b),
        <&[u8; 16]>::try_from(c),
        <&[u8; 16]>::try_from(d),
    ) {
        interleave16(o, a, b, c, d);
        return;
    }
    let mut i = 0;
    while i + 16 <= a.len() {
        if let (Ok(o), Ok(a), Ok(b), Ok(c), Ok(d)) = (
            <&mut [u8; 64]>::try_from(&mut dst[4 * i..4 * i + 64]),
            <&[u8; 16]>::try_from(&a[i..i + 16]),
            <&[u8; 16]>::try_from(&b[i..i + 16]),
            <&[u8; 16]>::try_from(&c[i..i + 16]),
            <&[u8; 16]>::try_from(&d[i..i + 16]),
        ) {
            interleave16(o, a, b, c, d);
        }
        i += 16;
    }
    if i + 8 <= a.len() {
        if let (Ok(o), Ok(a), Ok(b), Ok(c), Ok(d)) = (
            <&mut [u8; 32]>::try_from(&mut dst[4 * i..4 * i + 32]),
            <&[u8; 8]>::try_from(&a[i..i + 8]),
            <&[u8; 8]>::try_from(&b[i..i + 8]),
            <&[u8; 8]>::try_from(&c[i..i + 8]),
            <&[u8; 8]>::try_from(&d[i..i + 8]),
        ) {
            interleave8(o, a, b, c, d);
        }
        i += 8;
    }
    for (j, o) in dst[4 * i..].chunks_exact_mut(4).enumerate() {
        o.copy_from_slice(&[a[i + j], b[i + j], c[i + j], d[i + j]]);
    }
}

/// 4 x 8 bytes to 8 x 4: the 16-byte interleave on zero-extended halves, first half kept.
fn interleave8(o: &mut [u8; 32], a: &[u8; 8], b: &[u8; 8], c: &[u8; 8], d: &[u8; 8]) {
    let wide = |x: &[u8; 8]| {
        let mut w = [0u8; 16];
        w[..8].copy_from_slice(x);
        w
    };
    let mut full = [0u8; 64];
    interleave16(&mut full, &wide(a), &wide(b), &wide(c), &wide(d));
    o.copy_from_slice(&full[..32]);
}

/// 32 bytes to their 16 even-indexed and 16 odd-indexed ones.
#[cfg(target_arch = "x86_64")]
fn deinterleave32(x: &[u8; 32]) -> ([u8; 16], [u8; 16]) {
    // SAFETY: as for `interleave16`: SSE2 is baseline on x86_64, no pointers are involved.
    #[allow(unsafe_code)]
    unsafe {
        deinterleave32_sse2(x)
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "sse2")]
fn deinterleave32_sse2(x: &[u8; 32]) -> ([u8; 16], [u8; 16]) {
    use std::arch::x86_64::*;
    let [lo, hi]: [__m128i; 2] = bytemuck::cast(*x);
    let mask = _mm_set1_epi16(0x00ff);
    let even = _mm_packus_epi16(_mm_and_si128(lo, mask), _mm_and_si128(hi, mask));
    let odd = _mm_packus_epi16(_mm_srli_epi16(lo, 8), _mm_srli_epi16(hi, 8));
    (bytemuck::cast(even), bytemuck::cast(odd))
}

/// 32 bytes to their 16 even-indexed and 16 odd-indexed ones.
#[cfg(target_arch = "aarch64")]
fn deinterleave32(x: &[u8; 32]) -> ([u8; 16], [u8; 16]) {
    // SAFETY: as for `interleave16`: NEON is baseline on aarch64, no pointers are involved.
    #[allow(unsafe_code)]
    unsafe {
        deinterleave32_neon(x)
    }
}

#[cfg(target_arch = "aarch64")]
#[target_feature(enable = "neon")]
fn deinterleave32_neon(x: &[u8; 32]) -> ([u8; 16], [u8; 16]) {
    use std::arch::aarch64::*;
    let [lo, hi]: [uint8x16_t; 2] = bytemuck::cast(*x);
    (
        bytemuck::cast(vuzp1q_u8(lo, hi)),
        bytemuck::cast(vuzp2q_u8(lo, hi)),
    )
}

/// 32 bytes to their 16 even-indexed and 16 odd-indexed ones, portable.
#[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
fn deinterleave32(x: &[u8; 32]) -> ([u8; 16], [u8; 16]) {
    let (mut even, mut odd) = ([0u8; 16], [0u8; 16]);
    for i in 0..16 {
        even[i] = x[2 * i];
        odd[i] = x[2 * i + 1];
    }
    (even, odd)
}

/// 4 x 16 bytes to 16 x 4: eight byte/word unpacks (SSE2, baseline on x86_64).
#[cfg(target_arch = "x86_64")]
fn interleave16(o: &mut [u8; 64], a: &[u8; 16], b: &[u8; 16], c: &[u8; 16], d: &[u8; 16]) {
    // SAFETY: SSE2 is part of the x86_64 baseline, so the feature is always present; the
    // function only moves values between registers and arrays (no pointers).
    #[allow(unsafe_code)]
    unsafe {
        interleave16_sse2(o, a, b, c, d)
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "sse2")]
fn interleave16_sse2(o: &mut [u8; 64], a: &[u8; 16], b: &[u8; 16], c: &[u8; 16], d: &[u8; 16]) {
    use std::arch::x86_64::*;
    let v = |x: &[u8; 16]| -> __m128i { bytemuck::cast(*x) };
    let (a, b, c, d) = (v(a), v(b), v(c), v(d));
    let (ab_lo, ab_hi) = (_mm_unpacklo_epi8(a, b), _mm_unpackhi_epi8(a, b));
    let (cd_lo, cd_hi) = (_mm_unpacklo_epi8(c, d), _mm_unpackhi_epi8(c, d));
    let out: [__m128i; 4] = [
        _mm_unpacklo_epi16(ab_lo, cd_lo),
        _mm_unpackhi_epi16(ab_lo, cd_lo),
        _mm_unpacklo_epi16(ab_hi, cd_hi),
        _mm_unpackhi_epi16(ab_hi, cd_hi),
    ];
    *o = bytemuck::cast(out);
}

/// 4 x 16 bytes to 16 x 4: eight byte/halfword zips (NEON, baseline on aarch64).
#[cfg(target_arch = "aarch64")]
fn interleave16(o: &mut [u8; 64], a: &[u8; 16], b: &[u8; 16], c: &[u8; 16], d: &[u8; 16]) {
    // SAFETY: NEON is part of the aarch64 baseline, so the feature is always present; the
    // function only moves values between registers and arrays (no pointers).
    #[allow(unsafe_code)]
    unsafe {
        interleave16_neon(o, a, b, c, d)
    }
}

#[cfg(target_arch = "aarch64")]
#[target_feature(enable = "neon")]
fn interleave16_neon(o: &mut [u8; 64], a: &[u8; 16], b: &[u8; 16], c: &[u8; 16], d: &[u8; 16]) {
    use std::arch::aarch64::*;
    let v = |x: &[u8; 16]| -> uint8x16_t { bytemuck::cast(*x) };
    let (a, b, c, d) = (v(a), v(b), v(c), v(d));
    let h = vreinterpretq_u16_u8;
    let (ab_lo, ab_hi) = (h(vzip1q_u8(a, b)), h(vzip2q_u8(a, b)));
    let (cd_lo, cd_hi) = (h(vzip1q_u8(c, d)), h(vzip2q_u8(c, d)));
    let out: [uint8x16_t; 4] = [
        vreinterpretq_u8_u16(vzip1q_u16(ab_lo, cd_lo)),
        vreinterpretq_u8_u16(vzip2q_u16(ab_lo, cd_lo)),
        vreinterpretq_u8_u16(vzip1q_u16(ab_hi, cd_hi)),
        vreinterpretq_u8_u16(vzip2q_u16(ab_hi, cd_hi)),
    ];
    *o = bytemuck::cast(out);
}

/// 4 x 16 bytes to 16 x 4, portable.
#[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
fn interleave16(o: &mut [u8; 64], a: &[u8; 16], b: &[u8; 16], c: &[u8; 16], d: &[u8; 16]) {
    for i in 0..16 {
        o[4 * i..4 * i + 4].copy_from_slice(&[a[i], b[i], c[i], d[i]]);
    }
}

impl Op for PackedIm2Col {
    fn name(&self) -> StaticName {
        "PackedIm2col".into()
    }

    fn info(&self) -> TractResult<Vec<String>> {
        let g = &self.geo;
        Ok(vec![format!(
            "k:{} n:{} kernel:{}x{} stride:{}x{} groups:{} into {}",
            g.k, g.n, g.kh, g.kw, g.sy, g.sx, g.group, self.format
        )])
    }

    op_as_typed_op!();
}

impl EvalOp for PackedIm2Col {
    op_out_of_plan!();

    fn eval(&self, _ctx: &EvalContext, inputs: TVec<TValue>) -> TractResult<TVec<TValue>> {
        ensure!(
            inputs.len() == 1 || inputs.len() == 2,
            "PackedIm2col: {} inputs",
            inputs.len()
        );
        // The padding value is the input's zero point (a scalar, possibly held as i32).
        let pad = match inputs.get(1) {
            Some(p) => {
                ensure!(
                    p.len() == 1,
                    "PackedIm2col: padding value of shape {:?}",
                    p.shape()
                );
                let v = p.cast_to_scalar::<i32>()?;
                let byte = if self.dt.unquantized() == DatumType::U8 {
                    u8::try_from(v).ok()
                } else {
                    i8::try_from(v).ok().map(|b| b as u8)
                };
                byte.with_context(|| format!("PackedIm2col: padding value {v} for {:?}", self.dt))?
            }
            None => 0,
        };
        ensure!(
            inputs[0].datum_type() == self.dt,
            "PackedIm2col: input is {:?}, planned for {:?}",
            inputs[0].datum_type(),
            self.dt
        );
        Ok(tvec!(self
            .eval_bytes(inputs[0].as_bytes(), pad)?
            .into_tvalue()))
    }
}

impl TypedOp for PackedIm2Col {
    as_op!();

    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        let g = &self.geo;
        let pof = PackedExoticFact {
            format: self.format.clone(),
            k: g.k,
            mn: g.n.to_dim(),
        };
        Ok(tvec!(inputs[0]
            .datum_type
            .fact([g.batch, g.group])
            .with_exotic_fact(pof)))
    }
}
