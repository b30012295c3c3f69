// funicular's 3-D view of an equilibrium, drawn on a canvas element. The HTML report inlines this
// file (the report stays one offline page) and the explorer loads it. An orthographic projection
// (turn about the vertical, then tilt), painter's order by depth, viridis colours by tension as in
// the pictures (or by other values per link), drag to turn and wheel to zoom; no library.
// funicularView3D(canvas, data) draws `data` and returns {set(data, refit), draw()}: `set` draws a
// new equilibrium (null: none), keeping the turn and zoom, and keeping the framing too unless
// `refit`. The data (one format for both callers):
//   positions [[x, y, z], ...], links [[i, j], ...], tension [...], taut [...] (one per link),
//   supports [node, ...] with reactions [[fx, fy, fz], ...], contact_nodes [node, ...] with
//   contact_forces [[fx, fy, fz], ...]; optional: load_nodes with load_forces (point loads),
//   obstacles, scenario tables ({shape: "sphere", center, radius}, ellipsoid, box, halfspace),
//   force_unit, the unit the colour bar's tensions are labelled with ("N"; none if absent or ""), and
//   colour_values (one per link) with colour_label: the links coloured by these values (their strain,
//   say) instead of their tension, the colour bar labelled colour_label (no unit).
// The canvas's data-colour-bar attribute holds the colour bar's label as drawn.
function funicularView3D(canvas, data) {
  "use strict";
  const ctx = canvas.getContext("2d");
  const VIRIDIS = [[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]];
  let yaw = -0.6, pitch = 0.45, zoom = 1, drag = null;
  let d = null, values = [], tmin = 0, tmax = 1, centre = [0, 0, 0], size = 1, span = 1, rscale = 0, cscale = 0, lscale = 0;

  function longest(vectors) {
    let m = 0;
    for (const v of vectors || []) m = Math.max(m, Math.hypot(v[0], v[1], v[2]));
    return m;
  }
  function scaleFor(vectors, share, extent) {
    const m = longest(vectors);
    return m > 0 ? share * extent / m : 0;
  }
  // The box an obstacle takes up (none for a half-space, which has no end).
  function obstacleBox(o) {
    if (!o.center) return null;
    let half;
    if (o.shape === "sphere") half = [o.radius, o.radius, o.radius];
    else if (o.shape === "ellipsoid") half = o.semi_axes;
    else if (o.shape === "box") { const r = Math.hypot(o.half_sizes[0], o.half_sizes[1]); half = [r, r, o.half_sizes[2]]; }
    else return null;
    return [o.center.map((c, i) => c - half[i]), o.center.map((c, i) => c + half[i])];
  }
  function frame() {
    const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    const add = (p) => { for (let i = 0; i < 3; i++) { lo[i] = Math.min(lo[i], p[i]); hi[i] = Math.max(hi[i], p[i]); } };
    d.positions.forEach(add);
    for (const o of d.obstacles || []) { const box = obstacleBox(o); if (box) { add(box[0]); add(box[1]); } }
    span = Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) || 1;  // the arrows' scale
    const reach = scaleFor(d.reactions, 0.25, span);
    d.supports.forEach((n, j) => {  // the view holds the reaction arrows too
      add(d.positions[n].map((v, i) => v + reach * d.reactions[j][i]));
    });
    centre = lo.map((v, i) => (v + hi[i]) / 2);
    size = Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) || 1;
  }
  function prepare(next, refit) {
    d = next;
    values = d.colour_values || d.tension;
    tmin = Infinity; tmax = -Infinity;
    for (const t of values) { tmin = Math.min(tmin, t); tmax = Math.max(tmax, t); }
    if (!(tmax > tmin)) { tmin = Math.min(0, tmax); tmax = tmin + (tmax > 0 ? tmax : 1); }
    if (refit) frame();
    rscale = scaleFor(d.reactions, 0.25, span);
    cscale = scaleFor(d.contact_forces, 0.12, span);
    lscale = scaleFor(d.load_forces, 0.2, span);
  }
  function colour(t) {
    const u = Math.min(1, Math.max(0, (t - tmin) / (tmax - tmin))) * (VIRIDIS.length - 1);
    const k = Math.min(VIRIDIS.length - 2, Math.floor(u)), f = u - k;
    const c = VIRIDIS[k].map((v, i) => Math.round(v + f * (VIRIDIS[k + 1][i] - v)));
    return "rgb(" + c.join(",") + ")";
  }
  function scale() {
    return zoom * 0.62 * Math.min(canvas.width, canvas.height) / size;
  }
  function project(p) {
    const x = p[0] - centre[0], y = p[1] - centre[1], z = p[2] - centre[2];
    const cy = Math.cos(yaw), sy = Math.sin(yaw), cp = Math.cos(pitch), sp = Math.sin(pitch);
    const across = x * cy - y * sy, away = x * sy + y * cy, s = scale();
    return [canvas.width / 2 + s * across, canvas.height / 2 - s * (z * cp + away * sp), away * cp - z * sp];
  }
  function arrow(p, v, factor, style) {
    const a = project(p), b = project([p[0] + v[0] * factor, p[1] + v[1] * factor, p[2] + v[2] * factor]);
    const angle = Math.atan2(b[1] - a[1], b[0] - a[0]), head = 7;
    ctx.strokeStyle = ctx.fillStyle = style;
    ctx.lineWidth = 1.6;
    ctx.setLineDash([]);
    ctx.beginPath(); ctx.moveTo(a[0], a[1]); ctx.lineTo(b[0], b[1]); ctx.stroke();
    ctx.beginPath(); ctx.moveTo(b[0], b[1]);
    ctx.lineTo(b[0] - head * Math.cos(angle - 0.4), b[1] - head * Math.sin(angle - 0.4));
    ctx.lineTo(b[0] - head * Math.cos(angle + 0.4), b[1] - head * Math.sin(angle + 0.4));
    ctx.closePath(); ctx.fill();
  }
  // A closed curve centre + cos(t) u + sin(t) v, as 48 segments.
  function ring(c, u, v) {
    ctx.beginPath();
    for (let k = 0; k <= 48; k++) {
      const t = 2 * Math.PI * k / 48, q = project(c.map((ci, i) => ci + Math.cos(t) * u[i] + Math.sin(t) * v[i]));
      if (k === 0) ctx.moveTo(q[0], q[1]); else ctx.lineTo(q[0], q[1]);
    }
    ctx.stroke();
  }
  function segments(pairs) {
    ctx.beginPath();
    for (const [a, b] of pairs) { const p = project(a), q = project(b); ctx.moveTo(p[0], p[1]); ctx.lineTo(q[0], q[1]); }
    ctx.stroke();
  }
  function drawObstacle(o) {
    ctx.strokeStyle = "#6b7f99";
    ctx.lineWidth = 1;
    ctx.setLineDash([]);
    if (o.shape === "sphere" || o.shape === "ellipsoid") {
      const [a, b, c] = o.shape === "sphere" ? [o.radius, o.radius, o.radius] : o.semi_axes;
      if (o.shape === "sphere") {  // its outline is a circle in an orthographic projection
        const q = project(o.center);
        ctx.beginPath(); ctx.arc(q[0], q[1], o.radius * scale(), 0, 2 * Math.PI); ctx.stroke();
      }
      ctx.strokeStyle = "rgba(107, 127, 153, 0.55)";
      ring(o.center, [a, 0, 0], [0, b, 0]);
      ring(o.center, [a, 0, 0], [0, 0, c]);
      ring(o.center, [0, b, 0], [0, 0, c]);
    } else if (o.shape === "box") {
      const t = (o.angle || 0) * Math.PI / 180, [hx, hy, hz] = o.half_sizes;
      const corner = (i, j, k) => {
        const u = (i ? hx : -hx), v = (j ? hy : -hy);
        return [o.center[0] + u * Math.cos(t) - v * Math.sin(t), o.center[1] + u * Math.sin(t) + v * Math.cos(t), o.center[2] + (k ? hz : -hz)];
      };
      const edges = [];
      for (let i = 0; i < 2; i++) for (let j = 0; j < 2; j++) {
        edges.push([corner(i, j, 0), corner(i, j, 1)], [corner(i, 0, j), corner(i, 1, j)], [corner(0, i, j), corner(1, i, j)]);
      }
      segments(edges);
    } else if (o.shape === "halfspace") {  // a square of its plane around the structure, with its normal
      const n = o.normal, norm = Math.hypot(n[0], n[1], n[2]), m = n.map((v) => v / norm);
      const helper = Math.abs(m[2]) < 0.9 ? [0, 0, 1] : [1, 0, 0];
      const u = [m[1] * helper[2] - m[2] * helper[1], m[2] * helper[0] - m[0] * helper[2], m[0] * helper[1] - m[1] * helper[0]];
      const un = Math.hypot(u[0], u[1], u[2]), e1 = u.map((v) => v / un);
      const e2 = [m[1] * e1[2] - m[2] * e1[1], m[2] * e1[0] - m[0] * e1[2], m[0] * e1[1] - m[1] * e1[0]];
      const off = (centre[0] - o.point[0]) * m[0] + (centre[1] - o.point[1]) * m[1] + (centre[2] - o.point[2]) * m[2];
      const c = centre.map((v, i) => v - off * m[i]), h = 0.6 * size, lines = [];
      for (let k = -4; k <= 4; k++) {
        const f = k / 4 * h;
        lines.push([c.map((v, i) => v + f * e1[i] - h * e2[i]), c.map((v, i) => v + f * e1[i] + h * e2[i])]);
        lines.push([c.map((v, i) => v - h * e1[i] + f * e2[i]), c.map((v, i) => v + h * e1[i] + f * e2[i])]);
      }
      ctx.strokeStyle = "rgba(107, 127, 153, 0.45)";
      segments(lines);
    }
  }
  function draw() {
    ctx.fillStyle = "#ffffff";
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    if (d === null) { delete canvas.dataset.colourBar; return; }
    (d.obstacles || []).forEach(drawObstacle);
    const P = d.positions, L = d.links, Q = P.map(project);
    const order = L.map((_, k) => k);
    order.sort((a, b) => (Q[L[b][0]][2] + Q[L[b][1]][2]) - (Q[L[a][0]][2] + Q[L[a][1]][2]));
    ctx.lineWidth = 1.8;
    ctx.lineCap = "round";
    for (const k of order) {
      const a = Q[L[k][0]], b = Q[L[k][1]];
      ctx.strokeStyle = colour(values[k]);
      ctx.setLineDash(d.taut[k] ? [] : [5, 4]);
      ctx.beginPath(); ctx.moveTo(a[0], a[1]); ctx.lineTo(b[0], b[1]); ctx.stroke();
    }
    d.contact_nodes.forEach((i, j) => arrow(P[i], d.contact_forces[j], cscale, "royalblue"));
    (d.load_nodes || []).forEach((i, j) => arrow(P[i], d.load_forces[j], lscale, "green"));
    d.supports.forEach((i, j) => {
      if (rscale > 0) arrow(P[i], d.reactions[j], rscale, "crimson");
      const q = Q[i];
      ctx.fillStyle = "#000000";
      ctx.beginPath(); ctx.moveTo(q[0], q[1] - 7); ctx.lineTo(q[0] - 6, q[1] + 5); ctx.lineTo(q[0] + 6, q[1] + 5);
      ctx.closePath(); ctx.fill();
    });
    for (let i = 0; i <= 40; i++) {  // the colour bar
      ctx.fillStyle = colour(tmin + (tmax - tmin) * i / 40);
      ctx.fillRect(16 + 4 * i, canvas.height - 26, 4, 10);
    }
    ctx.fillStyle = "#222222";
    ctx.font = "12px system-ui, sans-serif";
    // (the unit of force the data carries: "" where the scenario declares none)
    const unit = d.colour_values || !d.force_unit ? "" : " " + d.force_unit;
    const name = d.colour_values ? d.colour_label : "tension";
    const text = name + " " + tmin.toPrecision(3) + " to " + tmax.toPrecision(3) + unit;
    ctx.fillText(text, 16, canvas.height - 32);
    canvas.dataset.colourBar = text;
  }
  canvas.addEventListener("pointerdown", (e) => {
    drag = [e.clientX, e.clientY];
    canvas.setPointerCapture(e.pointerId);
  });
  canvas.addEventListener("pointermove", (e) => {
    if (drag === null) return;
    yaw += (e.clientX - drag[0]) * 0.01;
    pitch = Math.max(-1.5, Math.min(1.5, pitch + (e.clientY - drag[1]) * 0.01));
    drag = [e.clientX, e.clientY];
    draw();
  });
  canvas.addEventListener("pointerup", () => { drag = null; });
  canvas.addEventListener("pointercancel", () => { drag = null; });
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    zoom = Math.max(0.1, Math.min(20, zoom * Math.exp(-e.deltaY * 0.001)));
    draw();
  }, { passive: false });

  function set(next, refit) {
    if (next) prepare(next, refit || d === null);
    else d = null;  // a blank canvas
    draw();
  }
  if (data) set(data, true);
  return { set, draw };
}
