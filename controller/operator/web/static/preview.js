/* The program preview: the path (rapids dashed, feeds, arcs, NURBS) in the work frame, the
   part already cut (pieces before the running line, and the tool's own trail) drawn apart,
   and the live tool. Plain canvas, no library. */
"use strict";

class PathPreview {
  constructor(canvas) {
    this.canvas = canvas;
    this.pieces = [];
    this.low = [0, 0]; this.high = [1, 1];
    this.tool = null;         // [x, y] in the work frame
    this.trail = [];          // the tool's path while a job of this program runs
    this.cutLine = 0;         // pieces of a line below this are cut
    this.dirty = true;
    const frame = () => { if (this.dirty) this.draw(); requestAnimationFrame(frame); };
    requestAnimationFrame(frame);
  }

  load(preview) {
    this.pieces = preview.pieces || [];
    this.low = preview.low_mm || [0, 0]; this.high = preview.high_mm || [1, 1];
    this.trail = []; this.cutLine = 0; this.dirty = true;
  }

  setTool(x, y, line, running) {
    if (this.tool && this.tool[0] === x && this.tool[1] === y && this.cutLine === line) return;
    this.tool = [x, y];
    if (running) {
      this.cutLine = line || 0;
      const last = this.trail[this.trail.length - 1];
      if (!last || last[0] !== x || last[1] !== y) this.trail.push([x, y]);
      if (this.trail.length > 20000) this.trail.splice(0, 10000);
    }
    this.canvas.dataset.tool = x.toFixed(3) + "," + y.toFixed(3);
    this.canvas.dataset.cut = String(this.trail.length);  // tool positions drawn as cut
    this.dirty = true;
  }

  transform() {
    const c = this.canvas, pad = 16;
    const lo = [Math.min(this.low[0], this.tool ? this.tool[0] : this.low[0]),
                Math.min(this.low[1], this.tool ? this.tool[1] : this.low[1])];
    const hi = [Math.max(this.high[0], this.tool ? this.tool[0] : this.high[0]),
                Math.max(this.high[1], this.tool ? this.tool[1] : this.high[1])];
    const w = Math.max(hi[0] - lo[0], 1e-3), h = Math.max(hi[1] - lo[1], 1e-3);
    const s = Math.min((c.width - 2 * pad) / w, (c.height - 2 * pad) / h);
    const ox = pad + ((c.width - 2 * pad) - s * w) / 2, oy = pad + ((c.height - 2 * pad) - s * h) / 2;
    return (x, y) => [ox + (x - lo[0]) * s, c.height - (oy + (y - lo[1]) * s)];
  }

  draw() {
    this.dirty = false;
    const ctx = this.canvas.getContext("2d"), at = this.transform();
    ctx.clearRect(0, 0, this.canvas.width, this.canvas.height);
    for (const piece of this.pieces) {
      const cut = piece.line < this.cutLine;
      ctx.strokeStyle = cut ? "#4caf50" : piece.kind === "rapid" ? "#777" : "#64b5f6";
      ctx.lineWidth = cut ? 2.5 : 1.2;
      ctx.setLineDash(piece.kind === "rapid" ? [4, 4] : []);
      ctx.beginPath();
      piece.points.forEach((p, i) => { const q = at(p[0], p[1]); i ? ctx.lineTo(q[0], q[1]) : ctx.moveTo(q[0], q[1]); });
      ctx.stroke();
    }
    ctx.setLineDash([]);
    if (this.trail.length > 1) {
      ctx.strokeStyle = "#ffb74d"; ctx.lineWidth = 1.5; ctx.beginPath();
      this.trail.forEach((p, i) => { const q = at(p[0], p[1]); i ? ctx.lineTo(q[0], q[1]) : ctx.moveTo(q[0], q[1]); });
      ctx.stroke();
    }
    if (this.tool) {
      const q = at(this.tool[0], this.tool[1]);
      ctx.fillStyle = "#ff5252"; ctx.beginPath(); ctx.arc(q[0], q[1], 6, 0, 2 * Math.PI); ctx.fill();
      ctx.strokeStyle = "#fff"; ctx.lineWidth = 1; ctx.beginPath();
      ctx.moveTo(q[0] - 10, q[1]); ctx.lineTo(q[0] + 10, q[1]); ctx.moveTo(q[0], q[1] - 10); ctx.lineTo(q[0], q[1] + 10); ctx.stroke();
    }
  }
}
window.PathPreview = PathPreview;
