// Depth to colour, as `stereoctl snapshot --colormap` draws it (pipeline/depth_io.cpp,
// ctl/output.cpp): the range from the 1st to the 99th percentile of the frame's depths
// (or a fixed one), spread in inverse depth so that the colours change most up close,
// on OpenCV's JET map (near red, far blue); no depth is black. Pure: no DOM.

// The 1st and 99th percentiles of the valid (finite, > 0) depths, in metres; from a
// sample of at most 200 000 of them, which places the ends within a fraction of a percent.
export function percentileRange(values) {
  const step = Math.max(1, Math.floor(values.length / 200000));
  const sample = [];
  for (let i = 0; i < values.length; i += step) {
    const z = values[i];
    if (z > 0 && Number.isFinite(z)) sample.push(z);
  }
  if (sample.length === 0) return null;
  const sorted = Float32Array.from(sample).sort();
  const at = (f) => sorted[Math.floor(f * (sorted.length - 1))];
  const near = at(0.01);
  // A flat scene still needs a range to spread over the colours.
  return { near, far: Math.max(at(0.99), near * 1.01 + 1e-3) };
}

// Position 0 (far) .. 1 (near) of depth z in [near, far], in inverse depth.
export function level(z, near, far) {
  const t = (1 / z - 1 / far) / (1 / near - 1 / far);
  return Math.min(1, Math.max(0, t));
}

// OpenCV's COLORMAP_JET at t in 0..1 (0 blue, 1 red), as [r, g, b] 0..255.
export function jet(t) {
  const c = (x) => 255 * Math.min(1, Math.max(0, 1.5 - Math.abs(4 * t - x)));
  return [c(3), c(2), c(1)];
}

// Tick marks for a colour bar from `near` to `far` metres: the ends, and round values
// (1, 2, 5 times a power of ten) between them where they do not crowd each other. Each
// tick: {depth_m, position} with position 0 (far end) .. 1 (near end).
export function colourBarTicks(near, far, count = 6) {
  const ticks = [{ depth_m: near, position: 1 }, { depth_m: far, position: 0 }];
  const minGap = 0.8 / count;
  const candidates = [];
  for (let p = Math.floor(Math.log10(near)) - 1; p <= Math.ceil(Math.log10(far)); ++p) {
    for (const m of [1, 2, 5]) {
      const z = m * 10 ** p;
      if (z > near && z < far) candidates.push(z);
    }
  }
  for (const z of candidates) {
    const position = level(z, near, far);
    if (ticks.every((t) => Math.abs(t.position - position) >= minGap)) {
      ticks.push({ depth_m: z, position });
    }
  }
  return ticks.sort((a, b) => a.position - b.position);
}

// "0.53 m", "12 m": as many decimals as the size of the number wants.
export function metres(z) {
  return `${z < 1 ? z.toFixed(2) : z < 10 ? z.toFixed(1) : z.toFixed(0)} m`;
}
