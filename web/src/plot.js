// The convergence plot: the unshot fraction of the emitted energy against time since the job
// started, on a log scale (progressive refinement shrinks it roughly geometrically, so a straight
// line on this plot is steady progress), with the job's convergence target as a dashed line.
// Drawn on a 2D canvas at the screen's pixel density.

export class ConvergencePlot {
  constructor(canvas) {
    this.canvas = canvas;
    this.points = []; // [seconds, unshot fraction]
    this.target = null;
    new ResizeObserver(() => this.draw()).observe(canvas);
  }

  clear(target) {
    this.points = [];
    this.target = target > 0 ? target : null;
    this.draw();
  }

  add(seconds, unshot) {
    if (!(seconds >= 0) || !(unshot > 0)) return; // log scale: a zero has no place (and means done)
    this.points.push([seconds, unshot]);
    this.draw();
  }

  // The plot in words, for screen readers (and the browser tests): its points and their range.
  describe() {
    const n = this.points.length;
    const canvas = this.canvas;
    canvas.dataset.points = String(n);
    if (n === 0) {
      canvas.setAttribute('aria-label', 'Unshot energy against time: no progress yet');
      return;
    }
    const [t0, v0] = this.points[0];
    const [t1, v1] = this.points[n - 1];
    canvas.setAttribute('aria-label', `Unshot energy against time, log scale: ${n} points, from ${v0.toExponential(2)} ` +
      `at ${t0.toFixed(2)} s to ${v1.toExponential(2)} at ${t1.toFixed(2)} s` +
      (this.target ? `; target ${this.target.toExponential(1)}` : ''));
  }

  draw() {
    this.describe();
    const canvas = this.canvas;
    const ratio = window.devicePixelRatio || 1;
    const width = canvas.clientWidth;
    const height = canvas.clientHeight;
    if (width === 0 || height === 0) return;
    canvas.width = Math.round(width * ratio);
    canvas.height = Math.round(height * ratio);
    const g = canvas.getContext('2d');
    g.setTransform(ratio, 0, 0, ratio, 0, 0);
    const style = getComputedStyle(canvas);
    const ink = style.color;
    const faint = style.getPropertyValue('--plot-grid').trim() || 'rgba(127,127,127,0.3)';
    const accent = style.getPropertyValue('--plot-line').trim() || '#e0a040';
    const font = parseFloat(style.fontSize) || 12;
    g.clearRect(0, 0, width, height);
    g.font = `${font * 0.85}px ${style.fontFamily}`;
    g.fillStyle = ink;

    const left = font * 3.2;
    const right = width - font;
    const top = font * 0.8;
    const bottom = height - font * 2.4;
    if (right - left < 20 || bottom - top < 20) return;

    const values = this.points.map((p) => p[1]);
    if (this.target) values.push(this.target);
    let lo = values.length ? Math.floor(Math.log10(Math.min(...values))) : -3;
    let hi = values.length ? Math.ceil(Math.log10(Math.max(...values))) : 0;
    if (hi <= lo) hi = lo + 1;
    hi = Math.max(hi, 0);
    lo = Math.min(lo, hi - 1);
    // A target far below the data (1e-30) would flatten the line: the axis stops three decades
    // under the data, and the target is then named instead of drawn.
    if (this.points.length > 0) lo = Math.max(lo, Math.floor(Math.log10(Math.min(...this.points.map((p) => p[1])))) - 3);
    const tMax = Math.max(1e-3, ...this.points.map((p) => p[0]));
    const x = (t) => left + (t / tMax) * (right - left);
    const y = (v) => top + ((hi - Math.log10(v)) / (hi - lo)) * (bottom - top);

    // Decades on y, about five steps on x.
    g.strokeStyle = faint;
    g.lineWidth = 1;
    g.textAlign = 'right';
    g.textBaseline = 'middle';
    const every = Math.max(1, Math.ceil((hi - lo) / 8));
    for (let d = lo; d <= hi; d += every) {
      const yy = Math.round(y(10 ** d)) + 0.5;
      g.beginPath();
      g.moveTo(left, yy);
      g.lineTo(right, yy);
      g.stroke();
      g.fillText(`1e${d}`, left - font * 0.3, yy);
    }
    const step = niceStep(tMax / 5);
    g.textAlign = 'center';
    g.textBaseline = 'top';
    for (let t = 0; t <= tMax * 1.0001; t += step) {
      const xx = Math.round(x(t)) + 0.5;
      g.beginPath();
      g.moveTo(xx, top);
      g.lineTo(xx, bottom);
      g.stroke();
      g.fillText(formatSeconds(t, step), xx, bottom + font * 0.3);
    }
    g.fillText('time since start (s)', (left + right) / 2, bottom + font * 1.3);

    if (this.target && Math.log10(this.target) < lo) {
      g.textAlign = 'right';
      g.textBaseline = 'bottom';
      g.fillText(`target ${this.target.toExponential(0)}: below the axis`, right, bottom - font * 0.2);
    } else if (this.target) {
      g.save();
      g.setLineDash([font * 0.4, font * 0.3]);
      g.strokeStyle = ink;
      g.beginPath();
      g.moveTo(left, y(this.target));
      g.lineTo(right, y(this.target));
      g.stroke();
      g.restore();
    }

    if (this.points.length > 0) {
      g.strokeStyle = accent;
      g.fillStyle = accent;
      g.lineWidth = Math.max(1.5, font * 0.15);
      g.beginPath();
      this.points.forEach(([t, v], i) => (i === 0 ? g.moveTo(x(t), y(v)) : g.lineTo(x(t), y(v))));
      g.stroke();
      const [t, v] = this.points[this.points.length - 1];
      g.beginPath();
      g.arc(x(t), y(v), g.lineWidth * 1.6, 0, 2 * Math.PI);
      g.fill();
    }
  }
}

function niceStep(raw) {
  const p = 10 ** Math.floor(Math.log10(raw));
  for (const m of [1, 2, 5, 10]) if (m * p >= raw) return m * p;
  return 10 * p;
}

function formatSeconds(t, step) {
  const digits = step >= 1 ? 0 : Math.min(3, Math.ceil(-Math.log10(step)));
  return t.toFixed(digits);
}
