// The explorer's page: the state is a scenario document (what a scenario file holds); every change
// sends it to /api/solve and draws the answer, then asks /api/check for LICQ and the second order of
// that answer, shown when they come. At most one solve of a scenario is in flight: changes made
// meanwhile only mark the state dirty, and the newest state is sent when the answer arrives.
// The readout only ever shows numbers of the state it describes: every change numbers the state
// (`version`), blanks the readout ("solving…"), and an answer or a check is shown only if it is of
// the newest state. A new scenario (`epoch`) also drops any answer still coming for the one before,
// picture included.
// Two pictures: a planar chain in an SVG whose supports and obstacles are dragged; a net or a chain
// in space in the 3-D view shared with the HTML report (funicularView3D, /view3d.js), whose supports
// and obstacles are changed with number fields.

const SVG = "http://www.w3.org/2000/svg";
const W = 800, H = 560;
const $ = (id) => document.getElementById(id);

let state = null;       // the scenario document being explored
let last = null;        // the last converged answer (the picture keeps it while a solve fails)
let view = null;        // world -> screen: {x0, y0, s}
let inFlight = null;     // the solve in flight: {epoch, version, state}
let dirty = false, solves = 0, answers = 0, checked = 0;
let epoch = 0;          // the scenario's number: a new scenario drops every answer for the one before
let version = 0;        // the state's number: the readout shows only answers and checks of the newest
let loading = 0;        // a scenario being loaded (its request's number; 0: none): no solve meanwhile
let start = null;       // the page's start (/api/start): the served state, the menus
const SERVED = ":served";  // the menu's entry for the scenario file funicular serve was given
let drag = null;        // {kind, index, start, original}
let space = false;      // the state is a net or lies in space: the 3-D view, not the SVG
let view3d = null;      // the 3-D view (made on the first answer in space)
let refit = true;       // frame the 3-D view anew on the next answer (a new scenario or node count)
let colourBy = "tension";  // what the links are coloured by: "tension", or "strain" where some link is elastic

const SHAPES = { 2: ["disk", "ellipse", "box", "halfplane"], 3: ["sphere", "ellipsoid", "box", "halfspace"] };
const GENERATORS = ["grid", "radial", "disk", "mesh"];

// The state's dimension as the scenario reader sees it: given, else 3 for a generated net, else 2.
function dimensionOf(s) {
  if (s.dimension) return s.dimension;
  return s.net && GENERATORS.some((key) => key in s.net) ? 3 : 2;
}

// ------------------------------------------------------------------ numbers and geometry
function fmt(x, digits = 6) {
  if (x === null || x === undefined) return "-";
  const text = Number(x).toPrecision(digits);
  return text.includes(".") ? text.replace(/\.?0+(?=e|$)/, "") : text;
}
// A number with its unit; the server says which (an answer's `units`: "" where the scenario declares none).
const withUnit = (text, symbol) => (symbol ? `${text} ${symbol}` : text);
const sx = (x) => (x - view.x0) * view.s;
const sy = (y) => (view.y0 - y) * view.s;
const nodeIndex = (node, n) => (node < 0 ? n + node : node);

function world(event) {
  const point = $("scene").createSVGPoint();
  point.x = event.clientX; point.y = event.clientY;
  const p = point.matrixTransform($("scene").getScreenCTM().inverse());
  return [view.x0 + p.x / view.s, view.y0 - p.y / view.s];
}

function fit(positions) {
  const xs = [], ys = [];
  const add = (x, y) => { xs.push(x); ys.push(y); };
  for (const s of state.supports) add(...s.position);
  for (const p of positions || []) add(...p);
  for (const o of state.obstacles || []) {
    if (o.center) { const r = o.radius || Math.max(...(o.semi_axes || o.half_size)); add(o.center[0] - r, o.center[1] - r); add(o.center[0] + r, o.center[1] + r); }
    if (o.point) add(...o.point);
  }
  const [xmin, xmax, ymin, ymax] = [Math.min(...xs), Math.max(...xs), Math.min(...ys), Math.max(...ys)];
  const w = Math.max(xmax - xmin, 0.5), h = Math.max(ymax - ymin, 0.5);
  const s = Math.min(W / (2 * w), H / (2 * h));  // room for the reaction arrows
  view = { s, x0: (xmin + xmax) / 2 - W / (2 * s), y0: (ymin + ymax) / 2 + H / (2 * s) };
}

// ------------------------------------------------------------------ talking to the server
async function post(path, body) {
  const response = await fetch(path, { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body) });
  let answer;
  try { answer = await response.json(); } catch { answer = { error: `the server answered ${response.status} without JSON.` }; }
  return answer;
}

// The state has changed: number it, blank the readout and solve it.
function requestSolve() {
  version += 1;
  showSolving();
  send();
}

function send() {
  if (loading) return;  // (the state is about to be replaced)
  if (inFlight && inFlight.epoch === epoch) { dirty = true; return; }
  // (a solve still in flight for the scenario before does not hold this one back: its answer is dropped)
  const ticket = { epoch, version, state: structuredClone(state) };
  inFlight = ticket; dirty = false;
  document.body.dataset.idle = "false";
  post("/api/solve", { state: ticket.state, start: last ? last.positions : null })
    .catch((error) => ({ error: `the server cannot be reached (${error.message}).` }))
    .then((answer) => {
      if (inFlight === ticket) inFlight = null;
      if (ticket.epoch === epoch) show(answer, ticket);
      document.body.dataset.answers = String(++answers);  // (a hook for tests: every answer, shown or dropped)
      if (inFlight !== null) return;
      if (dirty) send();
      else document.body.dataset.idle = "true";  // (a hook for tests: the picture is of the newest state)
    });
}

// The readout's cells that hold numbers (or verdicts) of one state.
const READOUT = ["energy", "max-tension", "max-strain", "iterations", "kkt", "licq", "second-order"];

function blank(text) {
  for (const id of READOUT) $(id).textContent = text;
  $("multiplier-note").textContent = "";
  document.querySelector("#link-table tbody").innerHTML = "";
}

// (`data-readout` on the body: solving, checking, done, error or not-converged; a hook for tests)
function showSolving() {
  blank("…");
  $("status").textContent = "solving…";
  $("status").className = "pending";
  $("status").title = "";
  $("error").textContent = "";
  document.body.dataset.readout = "solving";
}

function showError(message) {
  blank("");
  $("error").textContent = message;
  $("status").textContent = "error";
  $("status").className = "bad";
  $("status").title = "";
  document.body.dataset.readout = "error";
  if (!space && !view) fit(null);
  draw();
}

// An answer of this scenario: its picture (an older state's too: a drag is followed), and the readout
// if it is of the newest state.
function show(answer, ticket) {
  const newest = ticket.version === version;
  if (answer.error) { if (newest) showError(answer.error); return; }
  if (answer.converged) {
    if (!last || last.positions.length !== answer.positions.length) refit = true;
    last = answer;
    offerColouring(last);
  }
  if (!space && !view) fit(answer.positions);
  solves += 1;
  document.body.dataset.solves = String(solves);
  draw();
  if (newest) showAnswer(answer, ticket);
}

function showAnswer(answer, ticket) {
  $("status").textContent = answer.status;
  $("status").className = answer.converged ? "" : "bad";
  $("status").title = answer.message;
  if (!answer.converged) {
    blank("");
    $("error").textContent = `${answer.message}; the picture shows the last converged equilibrium.`;
    document.body.dataset.readout = "not-converged";
    return;
  }
  $("error").textContent = "";
  // (the energy's terms as the summary names them: the point loads' work and the links' strain energy)
  $("energy-terms").textContent = (answer.loads.length ? " - P . p" : "") + (answer.strain ? " + strain energy" : "");
  $("energy").textContent = withUnit(fmt(answer.energy, 10), answer.units.energy);
  $("max-tension").textContent = withUnit(fmt(answer.max_tension, 10), answer.units.force);
  $("strain-row").hidden = !answer.max_strain;
  if (answer.max_strain) $("max-strain").textContent = strainLine(answer);
  $("iterations").textContent = answer.iterations;
  const k = answer.kkt;
  $("kkt").textContent = `stationarity ${fmt(k.stationarity, 3)}, primal ${fmt(k.primal_feasibility, 3)}, dual ${fmt(k.dual_feasibility, 3)}, complementarity ${fmt(k.complementarity, 3)}`;
  $("length").value = fmt(answer.length, 8);
  $("mass").value = fmt(answer.mass, 8);
  $("multiplier-note").textContent = answer.formulation === "squared"
    ? "squared formulation: each link's multiplier is tension / (2 d_k); the tensions are the norm formulation's."
    : "norm formulation: each link's multiplier is its tension.";
  table(answer);
  requestCheck(answer, ticket);
}

// The summary's max strain line: the largest strain of an elastic link, where, and its stretch.
function strainLine(answer) {
  const m = answer.max_strain, n = answer.links.length;
  const between = state.net ? ` (nodes ${m.nodes[0]}-${m.nodes[1]})` : "";
  return `${fmt(m.strain, 4)} in link ${m.link}${between}, stretched by ${withUnit(fmt(m.stretch, 4), answer.units.length)} `
    + `(${m.elastic} of ${n} links elastic)`;
}

// LICQ and the second order of the answer just shown, from the point it found.
function requestCheck(answer, ticket) {
  $("licq").textContent = "checking…";
  $("second-order").textContent = "checking…";
  document.body.dataset.readout = "checking";
  const point = { positions: answer.positions, multipliers: { link: answer.multiplier, obstacle: answer.obstacle_multiplier } };
  post("/api/check", { state: ticket.state, point })
    .catch((error) => ({ error: `the server cannot be reached (${error.message}).` }))
    .then((checks) => {
      document.body.dataset.checks = String(++checked);  // (a hook for tests: every check answered, shown or not)
      if (ticket.version !== version) return;  // (the state has changed since: its own check follows its solve)
      if (checks.error) {
        $("licq").textContent = `not checked: ${checks.error}`;
        $("second-order").textContent = "not checked";
      } else {
        $("licq").textContent = checks.licq.text;
        const so = checks.second_order;
        $("second-order").textContent = `${so.verdict}: ${so.reason}`;
      }
      document.body.dataset.readout = "done";
    });
}

// Every link's multiplier, tension (and strain, where some link is elastic) and whether it is taut.
function table(answer) {
  const strain = answer.strain;
  const headers = ["link", "multiplier", "tension", ...(strain ? ["strain"] : []), "taut"];
  const symbols = ["", answer.units.multiplier, answer.units.force, ...(strain ? [""] : []), ""];
  $("link-table").querySelector("thead tr").innerHTML = headers
    .map((header, i) => `<th>${symbols[i] ? `${header} [${symbols[i]}]` : header}</th>`).join("");
  const rows = [];
  const shown = Math.min(answer.tension.length, 500);
  for (let k = 0; k < shown; k++) {
    const cells = [k, fmt(answer.multiplier[k], 8), fmt(answer.tension[k], 8), ...(strain ? [fmt(strain[k], 6)] : []), answer.taut[k] ? "taut" : "slack"];
    rows.push(`<tr>${cells.map((cell) => `<td>${cell}</td>`).join("")}</tr>`);
  }
  if (shown < answer.tension.length) rows.push(`<tr><td colspan="${headers.length}">(first ${shown} of ${answer.tension.length} links)</td></tr>`);
  document.querySelector("#link-table tbody").innerHTML = rows.join("");
}

// ------------------------------------------------------------------ drawing
function el(name, attributes, parent) {
  const node = document.createElementNS(SVG, name);
  for (const [key, value] of Object.entries(attributes)) node.setAttribute(key, value);
  parent.appendChild(node);
  return node;
}

function colour(fraction) {
  return `hsl(${Math.round(240 * (1 - fraction))}, 80%, 42%)`;
}

// What the links are coloured by in an answer: its tensions, or its strains where some link is
// elastic and strain is chosen; with the colour bar's name and unit (a strain has none).
function colouring(answer) {
  if (colourBy === "strain" && answer.strain) return { values: answer.strain, name: "strain", unit: "" };
  return { values: answer.tension, name: "tension", unit: answer.units.force };
}

// The colour toggle offers strain only where some link of the answer shown is elastic.
function offerColouring(answer) {
  const elastic = Boolean(answer && answer.strain);
  $("colour-by").querySelector("option[value=strain]").disabled = !elastic;
  if (!elastic) colourBy = "tension";
  $("colour-by").value = colourBy;
}

// The planar picture's colour bar: blue (0) to red (the largest value), labelled with what it shows.
function colourBar(shown, top) {
  const group = $("colour-bar");
  group.replaceChildren();
  let gradient = $("scene").querySelector("#bar-gradient");
  if (!gradient) {
    gradient = el("linearGradient", { id: "bar-gradient" }, $("scene").querySelector("defs"));
    for (let i = 0; i <= 4; i++) el("stop", { offset: i / 4, "stop-color": colour(i / 4) }, gradient);
  }
  el("rect", { x: 16, y: H - 26, width: 160, height: 10, fill: "url(#bar-gradient)" }, group);
  const text = el("text", { x: 16, y: H - 32, class: "label", "data-testid": "colour-bar-label" }, group);
  text.textContent = withUnit(`${shown.name} 0 to ${fmt(top, 3)}`, shown.unit);
}

function arrow(parent, [x, y], [fx, fy], scale, stroke, labelled) {
  const [x1, y1] = [sx(x), sy(y)], [x2, y2] = [sx(x + fx * scale), sy(y + fy * scale)];
  el("line", { x1, y1, x2, y2, stroke, "stroke-width": 2, "marker-end": "url(#head)" }, parent).style.color = stroke;
  if (!labelled) return;
  const text = el("text", { x: x2 + 4, y: y2 - 4, class: "label" }, parent);
  text.textContent = withUnit(fmt(Math.hypot(fx, fy), 4), last.units.force);
}

function drawObstacle(o, j, group, handles) {
  const id = `obstacle-${j}`;
  const common = { class: "obstacle", "data-testid": id, "data-kind": "obstacle", "data-index": j };
  let handle = null;
  if (o.shape === "disk") {
    el("circle", { ...common, cx: sx(o.center[0]), cy: sy(o.center[1]), r: o.radius * view.s }, group);
    handle = [o.center[0] + o.radius, o.center[1]];
  } else if (o.shape === "ellipse" || o.shape === "box") {
    const a = ((o.angle || 0) * Math.PI) / 180;
    const [u, v] = o.shape === "ellipse" ? o.semi_axes : o.half_size;
    const transform = `translate(${sx(o.center[0])} ${sy(o.center[1])}) rotate(${-(o.angle || 0)})`;
    if (o.shape === "ellipse") el("ellipse", { ...common, rx: u * view.s, ry: v * view.s, transform }, group);
    else el("rect", { ...common, x: -u * view.s, y: -v * view.s, width: 2 * u * view.s, height: 2 * v * view.s, rx: o.corner_radius * view.s, transform }, group);
    const [hu, hv] = o.shape === "ellipse" ? [u, 0] : [u, v];
    handle = [o.center[0] + hu * Math.cos(a) - hv * Math.sin(a), o.center[1] + hu * Math.sin(a) + hv * Math.cos(a)];
  } else if (o.shape === "halfplane") {
    const n = Math.hypot(...o.normal), [nx, ny] = [o.normal[0] / n, o.normal[1] / n], big = 1e3 / view.s;
    const corners = [[-ny, nx], [ny, -nx]].flatMap(([tx, ty], i) => {
      const edge = [o.point[0] + tx * big, o.point[1] + ty * big];
      const deep = [edge[0] - nx * big, edge[1] - ny * big];
      return i === 0 ? [edge, deep] : [deep, edge];
    });
    el("polygon", { ...common, points: corners.map(([x, y]) => `${sx(x)},${sy(y)}`).join(" ") }, group);
    handle = [o.point[0] + (nx * 60) / view.s, o.point[1] + (ny * 60) / view.s];
    el("line", { x1: sx(o.point[0]), y1: sy(o.point[1]), x2: sx(handle[0]), y2: sy(handle[1]), stroke: "#6b7f99" }, group);
  } else {
    const text = el("text", { ...common, x: 10, y: 20 + 14 * j, class: "label" }, group);
    text.textContent = `${o.name}: a ${o.shape} (not drawn, not draggable)`;
  }
  if (handle) el("circle", { class: "size-handle", "data-testid": `${id}-size`, "data-kind": "size", "data-index": j, cx: sx(handle[0]), cy: sy(handle[1]), r: 6 }, handles);
}

// The 3-D view's data (the format it shares with the report) from an answer; a net in the plane is
// shown in the vertical plane y = 0.
function viewData(answer) {
  const lift = (v) => (v.length === 3 ? v : [v[0], 0, v[1]]);
  return {
    positions: answer.positions.map(lift),
    links: answer.links,
    tension: answer.tension,
    taut: answer.taut,
    supports: answer.reactions.map((r) => r.node),
    reactions: answer.reactions.map((r) => lift(r.force)),
    contact_nodes: answer.contacts.map((c) => c.node),
    contact_forces: answer.contacts.map((c) => lift(c.force)),
    load_nodes: answer.loads.map((l) => l.node),
    load_forces: answer.loads.map((l) => lift(l.force)),
    obstacles: dimensionOf(state) === 3 ? state.obstacles : [],
    force_unit: answer.units.force,
    ...(colouring(answer).name === "strain" ? { colour_values: answer.strain, colour_label: "strain" } : {}),
  };
}

function drawSpace() {
  if (view3d === null) view3d = funicularView3D($("view3d"), null);
  if (!last) { view3d.set(null); return; }  // (a new scenario: no picture of the one before)
  view3d.set(viewData(last), refit);
  refit = false;
}

function draw() {
  if (space) { drawSpace(); return; }
  if (!view) return;
  for (const id of ["obstacles", "links", "arrows", "handles", "colour-bar"]) $(id).replaceChildren();
  let defs = $("scene").querySelector("defs");
  if (!defs) {
    defs = el("defs", {}, $("scene"));
    const marker = el("marker", { id: "head", viewBox: "0 0 10 10", refX: 9, refY: 5, markerWidth: 6, markerHeight: 6, orient: "auto-start-reverse" }, defs);
    el("path", { d: "M0,0 L10,5 L0,10 z", fill: "context-stroke" }, marker);
  }
  (state.obstacles || []).forEach((o, j) => drawObstacle(o, j, $("obstacles"), $("handles")));
  if (last && last.positions.length === state.chain.nodes) {
    const p = last.positions, shown = colouring(last), top = Math.max(...shown.values, 0);
    colourBar(shown, top);
    for (let k = 0; k + 1 < p.length; k++) {
      const attributes = { x1: sx(p[k][0]), y1: sy(p[k][1]), x2: sx(p[k + 1][0]), y2: sy(p[k + 1][1]), "stroke-width": 3, "stroke-linecap": "round" };
      if (last.taut[k]) attributes.stroke = colour(shown.values[k] / Math.max(top, 1e-300));
      else Object.assign(attributes, { stroke: "#999", "stroke-dasharray": "4 4" });
      el("line", attributes, $("links"));
    }
    if (p.length <= 300) for (const [x, y] of p) el("circle", { class: "node", cx: sx(x), cy: sy(y), r: 2 }, $("links"));
    const forces = [...last.reactions, ...last.contacts, ...last.loads].map((r) => Math.hypot(...r.force));
    const scale = (80 / view.s) / Math.max(...forces, 1e-300);
    for (const r of last.reactions) arrow($("arrows"), p[r.node], r.force, scale, "#1b7f3b", true);
    for (const l of last.loads) arrow($("arrows"), p[l.node], l.force, scale, "#7b3fb5", true);
    const contacts = [...last.contacts].sort((a, b) => Math.hypot(...b.force) - Math.hypot(...a.force)).slice(0, 40);
    // Only the largest contact force is labelled: neighbouring labels would overlap.
    contacts.forEach((c, i) => arrow($("arrows"), p[c.node], c.force, scale, "#d9730d", i === 0));
  }
  state.supports.forEach((s, i) => {
    el("rect", { class: "support", "data-testid": `support-${i}`, "data-kind": "support", "data-index": i, x: sx(s.position[0]) - 7, y: sy(s.position[1]) - 7, width: 14, height: 14 }, $("handles"));
  });
}

// ------------------------------------------------------------------ dragging
function onDown(event) {
  const target = event.target.closest("[data-kind]");
  if (!target || !view) return;
  const index = Number(target.dataset.index);
  drag = { kind: target.dataset.kind, index, start: world(event), original: structuredClone(target.dataset.kind === "support" ? state.supports[index] : state.obstacles[index]) };
  $("scene").setPointerCapture(event.pointerId);
  event.preventDefault();
}

function onMove(event) {
  if (!drag) return;
  const [x, y] = world(event), [dx, dy] = [x - drag.start[0], y - drag.start[1]];
  const o = drag.original;
  const moved = (p) => [p[0] + dx, p[1] + dy];
  if (drag.kind === "support") state.supports[drag.index].position = moved(o.position);
  else if (drag.kind === "obstacle") state.obstacles[drag.index] = { ...o, ...(o.center ? { center: moved(o.center) } : { point: moved(o.point) }) };
  else state.obstacles[drag.index] = resized(o, x, y);
  draw();
  requestSolve();
}

function resized(o, x, y) {
  const c = o.center || o.point, [dx, dy] = [x - c[0], y - c[1]], small = 1e-3;
  if (o.shape === "disk") return { ...o, radius: Math.max(Math.hypot(dx, dy), small) };
  if (o.shape === "halfplane") return Math.hypot(dx, dy) > small ? { ...o, normal: [dx, dy] } : o;
  const a = ((o.angle || 0) * Math.PI) / 180, u = dx * Math.cos(a) + dy * Math.sin(a), v = -dx * Math.sin(a) + dy * Math.cos(a);
  if (o.shape === "ellipse") { const k = Math.max(Math.abs(u), small) / o.semi_axes[0]; return { ...o, semi_axes: [o.semi_axes[0] * k, o.semi_axes[1] * k] }; }
  const half = [Math.max(Math.abs(u), small), Math.max(Math.abs(v), small)];
  return { ...o, half_size: half, corner_radius: Math.min(o.corner_radius, ...half) };
}

function onUp() { drag = null; }

// ------------------------------------------------------------------ controls
// A new scenario, shown as the menu's entry `entry` (a built-in's name, or SERVED).
function setState(next, entry, hint) {
  epoch += 1;
  state = next;
  state.obstacles = state.obstacles || [];
  last = null; view = null; refit = true;
  $("strain-row").hidden = true;
  space = state.net !== undefined || dimensionOf(state) === 3;
  // (the attribute: an SVG element has no hidden property)
  for (const id of ["scene", "hint-plane"]) $(id).toggleAttribute("hidden", space);
  for (const id of ["view3d", "hint-space"]) $(id).toggleAttribute("hidden", !space);
  $("height").textContent = dimensionOf(state) === 3 ? "z" : "y";
  $("shape").innerHTML = SHAPES[dimensionOf(state)].map((shape) => `<option>${shape}</option>`).join("");
  $("scenario-name").textContent = state.name || "";
  $("description").textContent = hint || state.description || "";
  $("scenario-list").value = entry;
  controls();
  // (no picture of the scenario before: the plane's is cleared, the 3-D view's set to nothing)
  if (space) draw();
  else for (const id of ["obstacles", "links", "arrows", "handles", "colour-bar"]) $(id).replaceChildren();
  requestSolve();
}

// A number field that calls `change` with its value (an empty or unreadable field changes nothing).
function numberField(value, change, testid, title) {
  const input = document.createElement("input");
  input.type = "number"; input.step = "any"; input.value = value;
  if (testid) input.dataset.testid = testid;
  if (title) input.title = title;
  input.onchange = () => { const x = Number(input.value); if (input.value !== "" && Number.isFinite(x)) change(x); };
  return input;
}

function removeButton(testid, remove) {
  const button = document.createElement("button");
  button.textContent = "remove";
  button.dataset.testid = testid;
  button.onclick = () => { remove(); controls(); draw(); requestSolve(); };
  return button;
}

function changed() { draw(); requestSolve(); }

// One field per number of a table (each component of a vector), named by its key.
function tableFields(item, table, prefix) {
  for (const [key, value] of Object.entries(table)) {
    if (Array.isArray(value)) {
      item.append(` ${key} `);
      value.forEach((v, k) => item.appendChild(numberField(v, (x) => { value[k] = x; changed(); }, `${prefix}-${key}-${k}`, `${key}[${k}]`)));
    } else if (typeof value === "number") {
      item.append(` ${key} `);
      item.appendChild(numberField(value, (x) => { table[key] = x; changed(); }, `${prefix}-${key}`, key));
    }
  }
}

function controls() {
  $("chain-controls").hidden = !state.chain;
  $("net-controls").hidden = !state.net;
  if (state.chain) {
    $("length").value = state.chain.length ?? "";
    $("nodes").value = state.chain.nodes;
    $("nodes-range").value = Math.min(state.chain.nodes, 200);
  }
  if (state.net) netControls(state.net);
  $("gravity").value = state.gravity ?? 1;
  $("mass").value = (state.chain || state.net).mass ?? "";
  const stiffness = stiffnessOf(state.chain || state.net);
  $("axial-stiffness").value = stiffness ?? "";
  $("axial-stiffness").placeholder = stiffness === undefined ? "per link" : "inf";
  $("formulation").value = state.formulation || "norm";
  $("support-controls").hidden = !(space && state.supports);
  $("support-list").innerHTML = "";
  if (space && state.supports) state.supports.forEach((s, i) => {
    const item = document.createElement("li");
    item.append(`node ${s.node}`);
    tableFields(item, { position: s.position }, `support-${i}`);
    $("support-list").appendChild(item);
  });
  $("load-list").innerHTML = "";
  (state.loads || []).forEach((l, i) => {
    const item = document.createElement("li");
    item.append("node ");
    item.appendChild(numberField(l.node, (x) => { l.node = x; changed(); }, `load-${i}-node`, "node"));
    tableFields(item, { force: l.force }, `load-${i}`);
    item.append(" ");
    item.appendChild(removeButton(`remove-load-${i}`, () => { state.loads.splice(i, 1); if (!state.loads.length) delete state.loads; }));
    $("load-list").appendChild(item);
  });
  $("obstacle-list").innerHTML = "";
  state.obstacles.forEach((o, j) => {
    const item = document.createElement("li");
    item.textContent = `${o.name} (${o.shape}) `;
    if (space) { tableFields(item, o, `obstacle-${j}`); item.append(" "); }
    item.appendChild(removeButton(`remove-obstacle-${j}`, () => state.obstacles.splice(j, 1)));
    $("obstacle-list").appendChild(item);
  });
}

function netControls(net) {
  const generator = GENERATORS.find((key) => key in net);
  $("grid-controls").hidden = !net.grid;
  if (net.grid) {
    $("grid-rows").value = net.grid[0];
    $("grid-columns").value = net.grid[1];
    // (a list of support nodes is kept as it is: the choice is only offered for the named sets)
    $("grid-supports").parentElement.toggleAttribute("hidden", Array.isArray(net.supports));
    $("grid-supports").value = typeof net.supports === "string" ? net.supports : "corners";
  }
  $("slack-control").hidden = !generator;
  $("slack").value = net.slack ?? "";
  $("net-kind").textContent = !generator ? "(links listed, supports below)" : generator === "grid" ? "" : `(a ${generator} net)`;
}

// ------------------------------------------------------------------ the links' axial stiffness
// The one EA of every link of a chain's or a net's table (axial_stiffness, or the per-link values
// when they are all the same: a chain's axial_stiffnesses, a fourth number in each net link row);
// null where every link is inextensible, undefined where the links' EA differ.
function stiffnessOf(table) {
  if (table.axial_stiffness !== undefined) return table.axial_stiffness;
  const each = table.axial_stiffnesses || (Array.isArray(table.links) ? table.links.map((row) => row[3] ?? null) : []);
  if (!each.length || each.every((ea) => ea === null)) return null;
  return each.every((ea) => ea === each[0]) ? each[0] : undefined;
}

// The EA field's text as the state's value: null (every link inextensible) for an empty field or
// inf; a number; anything else as typed, so that the scenario reader's sentence names the key.
function stiffnessValue(text) {
  const t = text.trim();
  if (t === "" || /^\+?inf(inity)?$/i.test(t)) return null;
  const x = Number(t);
  if (x === Infinity) return null;
  return Number.isFinite(x) ? x : t;
}

// One EA for every link: it replaces the per-link values (a chain's list, a net's link rows' fourth
// numbers).
function setStiffness(text) {
  const table = state.chain || state.net, ea = stiffnessValue(text);
  delete table.axial_stiffness;
  delete table.axial_stiffnesses;
  if (Array.isArray(table.links)) table.links = table.links.map((row) => row.slice(0, 3));
  if (ea !== null) table.axial_stiffness = ea;
  requestSolve();
}

// A chain of n nodes, total length and mass, its links' stiffness kept: one EA for every link, or
// the per-link values (another number of nodes gets the reader's sentence; the EA field replaces them).
function chainTable(nodes, length, mass) {
  const ea = stiffnessOf(state.chain), table = { nodes, length, mass };
  if (ea === undefined) table.axial_stiffnesses = state.chain.axial_stiffnesses;
  else if (ea !== null) table.axial_stiffness = ea;
  return table;
}

function totals() {
  // The page changes the chain as a whole: N nodes, the total length and mass (the last answer's).
  return { length: last ? last.length : Number($("length").value), mass: last ? last.mass : 1.0 };
}

function setNodes(n) {
  if (!Number.isInteger(n) || n < 2) return;
  const old = state.chain.nodes;
  const { length, mass } = totals();
  // Supports and point loads keep their place along the chain: the ends stay the ends, the others move
  // proportionally.
  for (const s of [...state.supports, ...(state.loads || [])]) {
    const i = nodeIndex(s.node, old);
    s.node = i === old - 1 ? -1 : Math.min(Math.round((i * (n - 1)) / (old - 1)), n - 1);
  }
  state.chain = chainTable(n, length, mass);
  controls();
  requestSolve();
}

function setMass(mass) {
  if (state.chain) state.chain = chainTable(state.chain.nodes, totals().length, mass);
  else { state.net.mass = mass; delete state.net.masses; delete state.net.linear_density; }
  requestSolve();
}

function setNet(change) {
  change(state.net);
  requestSolve();
}

function addObstacle(shape) {
  const names = new Set(state.obstacles.map((o) => o.name));
  let k = 1;
  while (names.has(`${shape} ${k}`)) k += 1;
  const name = `${shape} ${k}`;
  state.obstacles.push(dimensionOf(state) === 3 ? spaceObstacle(shape, name) : planeObstacle(shape, name));
  controls(); draw(); requestSolve();
}

function planeObstacle(shape, name) {
  const xs = state.supports.map((s) => s.position[0]), ys = state.supports.map((s) => s.position[1]);
  const span = Math.max(Math.max(...xs) - Math.min(...xs), 0.5 * totals().length, 0.2);
  const center = [(Math.max(...xs) + Math.min(...xs)) / 2, Math.min(...ys) - 0.4 * totals().length];
  const r = 0.15 * span;
  const tables = {
    disk: { shape, name, center, radius: r },
    ellipse: { shape, name, center, semi_axes: [1.5 * r, r], angle: 0.0 },
    box: { shape, name, center, half_size: [1.5 * r, r], corner_radius: 0.2 * r, angle: 0.0 },
    halfplane: { shape, name, point: [center[0], center[1] - r], normal: [0.0, 1.0] },
  };
  return tables[shape];
}

// A new obstacle in space: under the middle of the last equilibrium, a fifth of its size.
function spaceObstacle(shape, name) {
  const points = last ? last.positions : [[0, 0, 0]];
  const lo = [0, 1, 2].map((i) => Math.min(...points.map((p) => p[i])));
  const hi = [0, 1, 2].map((i) => Math.max(...points.map((p) => p[i])));
  const round = (x) => Number(x.toPrecision(3));  // (short numbers in the fields)
  const span = Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2], 0.2), r = round(0.2 * span);
  const center = [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2] - 0.6 * r].map(round);
  const tables = {
    sphere: { shape, name, center, radius: r },
    ellipsoid: { shape, name, center, semi_axes: [1.5 * r, r, r] },
    box: { shape, name, center, half_sizes: [r, r, r], radius: 0.0, angle: 0.0 },
    halfspace: { shape, name, point: [center[0], center[1], round(lo[2] + 0.2 * r)], normal: [0.0, 0.0, 1.0] },
  };
  return tables[shape];
}

// A point load of half the weight, straight down, on the middle node.
function addLoad() {
  const n = last ? last.positions.length : state.chain ? state.chain.nodes : 2;
  const weight = (last ? last.mass : 1.0) * (state.gravity ?? 1.0) || 1.0;
  const down = -0.5 * weight;
  state.loads = state.loads || [];
  state.loads.push({ node: Math.floor((n - 1) / 2), force: dimensionOf(state) === 3 ? [0.0, 0.0, down] : [0.0, down] });
  controls(); requestSolve();
}

async function save() {
  const answer = await post("/api/toml", { state });
  if (answer.error) { $("error").textContent = answer.error; return; }
  const link = document.createElement("a");
  link.href = URL.createObjectURL(new Blob([answer.toml], { type: "application/toml" }));
  link.download = `${state.name || "chain"}.toml`;
  document.body.appendChild(link);
  link.click();
  link.remove();
}

// Load the menu's entry `entry`: a built-in by its name, or the served file's state again. The
// readout is blanked at once, and any answer still coming for the scenario before is dropped.
async function load(entry, hint) {
  epoch += 1; version += 1;
  showSolving();
  const ticket = epoch;
  loading = entry === SERVED ? 0 : ticket;
  if (entry === SERVED) { setState(structuredClone(start.state), entry, hint); return; }
  const answer = await post("/api/load", { name: entry });
  if (loading !== ticket) return;  // (another scenario was asked for since)
  loading = 0;
  if (answer.error) { showError(answer.error); return; }
  setState(answer.state, entry, hint);
}

// The menu: every built-in, and first the scenario file funicular serve was given, if it was a file.
function menu(served) {
  const list = $("scenario-list");
  if (served.file) list.appendChild(new Option(`file: ${served.file}`, SERVED));
  for (const name of Object.keys(start.scenarios)) list.appendChild(new Option(name, name));
  return served.file ? SERVED : served.builtin;
}

async function main() {
  start = await (await fetch("/api/start")).json();
  const entry = menu(start.served);
  for (const [name, hint] of Object.entries(start.presets)) {
    const button = document.createElement("button");
    button.textContent = name;
    button.title = hint;
    button.dataset.testid = `preset-${name}`;
    button.onclick = () => load(name, hint);
    $("presets").appendChild(button);
  }
  $("load").onclick = () => load($("scenario-list").value);
  $("save").onclick = save;
  $("add").onclick = () => addObstacle($("shape").value);
  $("add-load").onclick = addLoad;
  $("mass").onchange = () => setMass(Number($("mass").value));
  $("grid-rows").onchange = () => setNet((net) => { net.grid = [Number($("grid-rows").value), net.grid[1]]; });
  $("grid-columns").onchange = () => setNet((net) => { net.grid = [net.grid[0], Number($("grid-columns").value)]; });
  $("grid-supports").onchange = () => setNet((net) => { net.supports = $("grid-supports").value; });
  $("slack").onchange = () => setNet((net) => { net.slack = Number($("slack").value); delete net.link_length; });
  $("nodes-range").oninput = () => setNodes(Number($("nodes-range").value));
  $("nodes").onchange = () => setNodes(Number($("nodes").value));
  $("length").onchange = () => { state.chain = chainTable(state.chain.nodes, Number($("length").value), totals().mass); requestSolve(); };
  $("axial-stiffness").onchange = () => setStiffness($("axial-stiffness").value);
  $("colour-by").onchange = () => { colourBy = $("colour-by").value; draw(); };
  $("gravity").onchange = () => { state.gravity = Number($("gravity").value); requestSolve(); };
  $("formulation").onchange = () => { state.formulation = $("formulation").value; requestSolve(); };
  const scene = $("scene");
  scene.addEventListener("pointerdown", onDown);
  scene.addEventListener("pointermove", onMove);
  scene.addEventListener("pointerup", onUp);
  scene.addEventListener("pointercancel", onUp);
  document.body.dataset.solves = "0";
  document.body.dataset.answers = "0";
  document.body.dataset.checks = "0";
  setState(structuredClone(start.state), entry);
}

main();
