// The ConAg viewer page: draws the pictures of nodes/viewer.py (see viewer/scene.py for their
// fields). Live: a Server-Sent Events stream of pictures. Recording: a timeline to scrub and play.
"use strict";
const COLOURS = { food: "#3a9d23", water: "#2a6fdb", brick: "#b5462f", wall: "#555555",
                  site: "#f2d27a", filled: "#e0a100", agent: "#6a3d9a", dead: "#aaaaaa", heading: "#111111",
                  cue_site: "#00838f", cue_supply: "#ef6c00" };
const DISC_R = 0.5, AGENT_R = 0.3, MARGIN = 10;
const canvas = document.getElementById("world"), ctx = canvas.getContext("2d");
const viewer = window.viewer = { picture: null, mode: null, selectedAgent: null, selectedDisc: null,
                                 moving: false, frames: 0, scale: 1, ox: 0, oy: 0 };

viewer.toCanvas = (x, y) => [viewer.ox + x * viewer.scale, viewer.oy - y * viewer.scale];
viewer.toWorld = (px, py) => [(px - viewer.ox) / viewer.scale, (viewer.oy - py) / viewer.scale];

const MAX_W = 820, MAX_H = 620;
function fit(p) {  // the canvas takes the world's shape, at most MAX_W x MAX_H pixels
  const s = Math.min((MAX_W - 2 * MARGIN) / p.width, (MAX_H - 2 * MARGIN) / p.height);
  const w = Math.round(p.width * s + 2 * MARGIN), h = Math.round(p.height * s + 2 * MARGIN);
  if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
  viewer.scale = s; viewer.ox = MARGIN; viewer.oy = MARGIN + p.height * s;
}

function circle(g, x, y, r, fill) {  // on the 2-D context g (the page's canvas or the scenery's)
  const [px, py] = viewer.toCanvas(x, y);
  g.beginPath(); g.arc(px, py, r * viewer.scale, 0, 2 * Math.PI); g.fillStyle = fill; g.fill();
}

function cell(g, x, y, fill, inset) {
  const s = viewer.scale, [px, py] = viewer.toCanvas(x - 0.5, y + 0.5);
  g.fillStyle = fill; g.fillRect(px + inset, py + inset, s - 2 * inset, s - 2 * inset);
}

// A cue (a mark a foreman put on the floor, docs/society.md), centred on pixel (px, py) of a
// cell s pixels wide: a cross for a site cue ("drop a brick here"), a diamond outline for a
// supply cue ("take bricks from around here"). Both fit inside a disc, so a brick lying on a
// marked cell hides its mark, as it hides it from the agents' sensors.
function cueMark(g, px, py, s, kind) {
  const a = (kind === "site" ? 0.3 : 0.38) * s;
  g.beginPath();
  if (kind === "site") { g.moveTo(px - a, py - a); g.lineTo(px + a, py + a); g.moveTo(px - a, py + a); g.lineTo(px + a, py - a); }
  else { g.moveTo(px + a, py); g.lineTo(px, py + a); g.lineTo(px - a, py); g.lineTo(px, py - a); g.closePath(); }
  g.strokeStyle = COLOURS["cue_" + kind]; g.lineWidth = Math.max(2, 0.1 * s); g.stroke();
}

// The world is drawn in two layers. The scenery (border, walls, sites, cues, discs) changes only
// when a brick is grabbed or dropped or a cue put or taken, so it is painted on an offscreen canvas when it changes and
// copied; each picture repaints only the bodies over it. Software-rendered in a browser on the
// run's own cores, every arc counts (docs/results/benchmarks.md, viewer overhead).
const scenery = { canvas: document.createElement("canvas"), key: null };

function sameRows(a, b) {  // two lists of [x, y, ...] rows, equal element for element
  if (!a || !b || a.length !== b.length) return false;
  for (let i = 0; i < a.length; i++) {
    const u = a[i], v = b[i];
    if (u.length !== v.length) return false;
    for (let j = 0; j < u.length; j++) if (u[j] !== v[j]) return false;
  }
  return true;
}

function paintScenery(p) {
  const k = scenery.key;
  if (k && k.w === canvas.width && k.h === canvas.height && k.scale === viewer.scale && sameRows(k.walls, p.walls)
      && sameRows(k.sites, p.sites) && sameRows(k.cues, p.cues) && sameRows(k.discs, p.discs)) return;
  const c = scenery.canvas;
  c.width = canvas.width; c.height = canvas.height;  // setting the size clears it, even the same size
  const g = c.getContext("2d"), [x0, y0] = viewer.toCanvas(0, p.height);
  g.strokeStyle = "#888"; g.lineWidth = 1; g.strokeRect(x0, y0, p.width * viewer.scale, p.height * viewer.scale);
  for (const [x, y] of p.walls) cell(g, x, y, COLOURS.wall, 0);
  for (const [x, y, filled] of p.sites) cell(g, x, y, filled ? COLOURS.filled : COLOURS.site, 1);
  for (const [x, y, kind] of p.cues || []) cueMark(g, ...viewer.toCanvas(x, y), viewer.scale, kind);  // under discs and bodies
  for (const [x, y, kind] of p.discs) circle(g, x, y, DISC_R * 0.92, COLOURS[kind]);
  scenery.key = { w: canvas.width, h: canvas.height, scale: viewer.scale, walls: p.walls, sites: p.sites,
                  cues: p.cues || [], discs: p.discs };
  viewer.sceneryPaints = (viewer.sceneryPaints || 0) + 1;
}

// The legend: a swatch per thing the world draws, painted once with the world's own strokes.
const LEGEND = [["food", "food"], ["water", "water"], ["brick", "brick"], ["site", "drop site"],
                ["filled", "filled site"], ["wall", "wall"], ["agent", "agent"],
                ["cue_site", "site cue: drop here"], ["cue_supply", "supply cue: take bricks"]];
function drawLegend() {
  const box = document.getElementById("legend"), S = 16;
  for (const [item, label] of LEGEND) {
    const span = document.createElement("span"), c = document.createElement("canvas"), g = c.getContext("2d");
    c.width = c.height = S; c.dataset.item = item;
    if (item.startsWith("cue_")) { g.fillStyle = COLOURS.site; g.fillRect(0, 0, S, S); cueMark(g, S / 2, S / 2, S, item.slice(4)); }
    else if (["site", "filled", "wall"].includes(item)) { g.fillStyle = COLOURS[item]; g.fillRect(1, 1, S - 2, S - 2); }
    else { g.beginPath(); g.arc(S / 2, S / 2, (item === "agent" ? AGENT_R / DISC_R : 0.92) * S / 2, 0, 2 * Math.PI);
           g.fillStyle = COLOURS[item]; g.fill(); }
    span.appendChild(c); span.appendChild(document.createTextNode(label)); box.appendChild(span);
  }
}
drawLegend();

function setText(id, text) {  // DOM writes only when the text changes: each one costs a layout
  const e = document.getElementById(id);
  if (e.textContent !== text) e.textContent = text;
}

function draw(p) {
  viewer.picture = p;
  if (!p.width) { setText("status", "waiting for the world's first view..."); return; }
  fit(p);
  paintScenery(p);
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  ctx.drawImage(scenery.canvas, 0, 0);
  if (viewer.selectedDisc) {
    const [px, py] = viewer.toCanvas(viewer.selectedDisc[0], viewer.selectedDisc[1]);
    ctx.beginPath(); ctx.arc(px, py, DISC_R * viewer.scale, 0, 2 * Math.PI);
    ctx.strokeStyle = "#000"; ctx.lineWidth = 2; ctx.stroke();
  }
  ctx.font = "11px sans-serif";
  for (const a of p.agents) {
    circle(ctx, a.x, a.y, AGENT_R, a.alive ? COLOURS.agent : COLOURS.dead);
    const [px, py] = viewer.toCanvas(a.x, a.y), r = AGENT_R * viewer.scale;
    const hx = Math.cos(a.heading), hy = -Math.sin(a.heading);
    ctx.beginPath(); ctx.moveTo(px, py); ctx.lineTo(px + hx * r * 1.9, py + hy * r * 1.9);
    ctx.strokeStyle = COLOURS.heading; ctx.lineWidth = 2; ctx.stroke();
    if (a.holding) { ctx.beginPath(); ctx.arc(px + hx * r * 1.9, py + hy * r * 1.9, r * 0.55, 0, 2 * Math.PI);
                     ctx.fillStyle = COLOURS.brick; ctx.fill(); }
    if (a.id === viewer.selectedAgent) {
      ctx.beginPath(); ctx.arc(px, py, r * 1.6, 0, 2 * Math.PI); ctx.strokeStyle = "#c2185b"; ctx.lineWidth = 2; ctx.stroke();
    }
    ctx.fillStyle = "#000"; ctx.fillText(a.id, px + r + 2, py - r - 2);
  }
  const total = p.sites_total ?? p.sites.length, filled = p.sites_filled ?? p.sites.filter(s => s[2]).length;
  const alive = p.agents_alive ?? p.agents.filter(a => a.alive).length;
  setText("status", `tick ${p.tick}   sites ${filled}/${total}   agents alive ${alive}/${p.agents.length}` +
    (p.completed ? "   COMPLETE" : "") + (p.scenario ? `   (${p.scenario}, ${p.mode})` : ""));
  if (p.progress) viewer.progress = p.progress;
  drawChart(viewer.progress || [], total, p.tick);
  drawAgents(p);
  viewer.frames += 1;
}

function drawChart(points, total, tick) {
  const c = document.getElementById("chart"), g = c.getContext("2d");
  const tmax = points.length ? Math.max(points[points.length - 1][0], 1) : 1;
  const X = t => 4 + (c.width - 8) * t / tmax;
  // Redrawn when a pixel of it would change: a new point, the count, a 1% longer time axis or the marker
  const key = [points.length, points.length && points[points.length - 1][1], total,
               Math.round(100 * Math.log(tmax)), Math.round(X(tick))].join();
  if (key === viewer.chartKey) return;
  viewer.chartKey = key;
  g.clearRect(0, 0, c.width, c.height);
  g.strokeStyle = "#ccc"; g.strokeRect(0.5, 0.5, c.width - 1, c.height - 1);
  if (!points.length) return;
  const ymax = Math.max(total, 1, ...points.map(q => q[1]));
  const Y = n => c.height - 4 - (c.height - 8) * n / ymax;
  g.beginPath(); g.strokeStyle = COLOURS.filled; g.lineWidth = 2;
  points.forEach(([t, n], i) => i ? g.lineTo(X(t), Y(n)) : g.moveTo(X(t), Y(n)));
  g.stroke();
  g.strokeStyle = "#c2185b"; g.lineWidth = 1; g.beginPath(); g.moveTo(X(tick), 0); g.lineTo(X(tick), c.height); g.stroke();
  g.fillStyle = "#333"; g.font = "11px sans-serif"; g.fillText(`${total} sites, ${tmax} ticks`, 8, 14);
}

function drawAgents(p) {
  const body = document.querySelector("#agents tbody");
  const rows = JSON.stringify([viewer.selectedAgent, p.agents.map(a => [a.id, a.alive, a.behaviour, a.holding])]);
  if (rows === viewer.rows) { drawDetails(p); return; }  // the table only when it changed: DOM work is the dearest
  viewer.rows = rows;
  body.innerHTML = "";
  for (const a of p.agents) {
    const tr = document.createElement("tr");
    tr.className = "agent" + (a.alive ? "" : " dead") + (a.id === viewer.selectedAgent ? " selected" : "");
    tr.dataset.id = a.id;
    for (const v of [a.id, a.alive ? "yes" : "no", a.behaviour || "?", a.holding ? "brick" : ""]) {
      const td = document.createElement("td"); td.textContent = v; tr.appendChild(td);
    }
    tr.onclick = () => selectAgent(a.id);
    body.appendChild(tr);
  }
  drawDetails(p);
}

function drawDetails(p) {
  const a = p.agents.find(q => q.id === viewer.selectedAgent);
  if (!a) { setText("details", "none"); return; }
  const lines = [`${a.id} at (${a.x.toFixed(2)}, ${a.y.toFixed(2)}), heading ${(a.heading * 180 / Math.PI).toFixed(0)} deg`,
                 `alive ${a.alive}, holding ${a.holding ? "a brick" : "nothing"}`];
  if (a.behaviour) {
    lines.push(`behaviour ${a.behaviour} (report of tick ${a.state_tick}), ${a.sites_open} sites believed open`);
    if (a.blocker) lines.push(`blocker: ${a.blocker}`);
    lines.push("ticks per behaviour: " + Object.entries(a.behaviour_ticks || {}).map(([k, v]) => `${k} ${v}`).join(", "));
  } else lines.push("no AgentState report yet (agents send one every 100 ticks)");
  if (a.state_nodes) {
    lines.push(`state nodes (tick ${a.decision_tick}): ` + Object.entries(a.state_nodes).map(([k, v]) => `${k} ${v}`).join(", "));
    lines.push(`arm ${a.arm}, motor ${a.motor}`);
  } else lines.push("state nodes: published by learning students only (Decision)");
  setText("details", lines.join("\n"));
}

// the selected agent's maps: ESMs grey (dark = sure), NMs bright near a goal, dark far, black unreachable
const MAP_ORDER = ["food", "water", "brick", "obstacle", "config", "agent", "config_nm", "brick_nm", "matching"];
const painted = {};  // layer name -> the cells its canvas shows (of whichever agent is selected)
async function loadMaps() {  // asked for: on a click, and for each picture of a recording
  const id = viewer.selectedAgent;
  if (!id) { showMaps(null, null); return; }
  const tick = viewer.picture ? viewer.picture.tick : 0;
  showMaps(id, await (await fetch(`/api/maps?agent=${encodeURIComponent(id)}&tick=${tick}`)).json());
}

function showMaps(id, m) {  // live, the viewer also pushes them once a second when they change
  const note = document.getElementById("mapsnote"), box = document.getElementById("maps");
  if (!id) { box.innerHTML = ""; note.textContent = ""; viewer.mapsShown = null; return; }
  if (id !== viewer.selectedAgent) return;  // an answer for the agent shown before
  viewer.maps = m;
  if (!m.size) { box.innerHTML = ""; viewer.mapsShown = null;
    note.textContent = "no maps from this agent (a viewer or recorder asks for them with --maps-every N)"; return; }
  const shown = `${id} ${m.tick} ${m.size}`;
  if (shown === viewer.mapsShown) return;  // the same snapshot: nothing to paint
  viewer.mapsShown = shown;
  note.textContent = `maps of ${id} at tick ${m.tick}, ${m.size} x ${m.size} cells, the agent in the centre`;
  for (const name of MAP_ORDER) {
    const cells = m.layers[name];
    let c = box.querySelector(`canvas[data-layer="${name}"]`);
    if (!cells) { if (c) c.parentElement.remove(); continue; }
    if (!c) {  // one figure per layer, made once and painted again for each snapshot
      const fig = document.createElement("figure"), cap = document.createElement("figcaption");
      c = document.createElement("canvas"); c.dataset.layer = name; cap.textContent = name; delete painted[name];
      fig.appendChild(c); fig.appendChild(cap);
      const after = MAP_ORDER.slice(MAP_ORDER.indexOf(name) + 1)
        .map(n => box.querySelector(`canvas[data-layer="${n}"]`)).find(Boolean);
      box.insertBefore(fig, after ? after.parentElement : null);
    }
    if (c.width !== m.size) { c.width = c.height = m.size; c.style.width = c.style.height = `${m.size * 2}px`; }
    // A layer that did not change since it was painted (a food ESM, mostly) is not painted again:
    // each canvas painted is one more for the browser to composite, on the run's own cores.
    if (painted[name] === cells) continue;
    painted[name] = cells;
    const bytes = atob(cells);  // base64 of the size x size cell values (viewer/scene.py, maps_picture)
    const g = c.getContext("2d"), img = g.createImageData(m.size, m.size), nm = name.endsWith("_nm");
    for (let i = 0; i < bytes.length; i++) {
      const v = bytes.charCodeAt(i);
      let r, gr, b;
      if (nm) { if (v >= 127) { r = gr = b = 0; } else { const k = Math.max(0, 1 - v / 40); r = 255 * k; gr = 200 * k; b = 60 * k; } }
      else { r = gr = b = 255 - 2 * v; }
      const o = 4 * i; img.data[o] = r; img.data[o + 1] = gr; img.data[o + 2] = b; img.data[o + 3] = 255;
    }
    const mid = (m.size >> 1) * m.size + (m.size >> 1); img.data.set([200, 30, 90, 255], 4 * mid);
    g.putImageData(img, 0, 0);
  }
}

function selectAgent(id) { viewer.selectedAgent = id; if (viewer.picture) draw(viewer.picture); loadMaps(); }

function nearest(items, x, y, reach) {
  let best = null, bd = reach;
  for (const it of items) { const d = Math.hypot(it[0] - x, it[1] - y); if (d <= bd) { bd = d; best = it; } }
  return best;
}

canvas.addEventListener("click", (ev) => {
  const p = viewer.picture; if (!p || !p.width) return;
  const r = canvas.getBoundingClientRect();
  const [x, y] = viewer.toWorld(ev.clientX - r.left, ev.clientY - r.top);
  if (viewer.moving && viewer.selectedDisc) { perturb("move", viewer.selectedDisc, [x, y]); return; }
  const agent = nearest(p.agents.map(a => [a.x, a.y, a.id]), x, y, 0.6);
  if (agent) { selectAgent(agent[2]); return; }
  const disc = nearest(p.discs, x, y, 0.6);
  viewer.selectedDisc = disc;
  document.getElementById("disc").textContent = disc ? `${disc[2]} at (${disc[0]}, ${disc[1]})` : "none";
  const live = viewer.mode === "live";
  document.getElementById("remove").disabled = document.getElementById("move").disabled = !(disc && live);
  draw(p);
});

async function perturb(op, disc, to) {
  viewer.moving = false;
  const body = { op, x: disc[0], y: disc[1], kind: disc[2], to_x: to ? to[0] : 0, to_y: to ? to[1] : 0 };
  const res = await fetch("/api/perturb", { method: "POST", headers: { "Content-Type": "application/json" },
                                            body: JSON.stringify(body) });
  const out = await res.json();
  document.getElementById("perturbed").textContent = (out.ok ? "done: " : "refused: ") + out.message;
  viewer.lastPerturb = out;
  viewer.selectedDisc = null;
  document.getElementById("disc").textContent = "none";
  document.getElementById("remove").disabled = document.getElementById("move").disabled = true;
}
document.getElementById("remove").onclick = () => viewer.selectedDisc && perturb("remove", viewer.selectedDisc);
document.getElementById("move").onclick = () => { viewer.moving = true;
  document.getElementById("perturbed").textContent = "click where the disc goes"; };

// live: pictures pushed at the display rate ---------------------------------------------------
function live() {
  const es = new EventSource("/api/events");
  // Pictures are drawn at the browser's next paint, the newest only: a page that falls behind
  // (or a hidden tab, which gets no paints) skips pictures instead of queueing them.
  let pending = null;
  es.onmessage = (ev) => {
    if (pending === null) requestAnimationFrame(() => { const p = pending; pending = null;
                                                        if (!viewer.frozen) draw(JSON.parse(p)); });
    pending = ev.data;  // parsed only if it is drawn
  };  // frozen: tests read one picture
  // the shown agent's maps, pushed when they change (about once a second; nodes/viewer.py)
  es.addEventListener("maps", (ev) => { const m = JSON.parse(ev.data); if (!viewer.frozen) showMaps(m.agent, m); });
  fetch("/api/scene").then(r => r.json()).then(p => { if (!viewer.frames) draw(p); });
}

// recording: a timeline to scrub and play ------------------------------------------------------
async function recording(info) {
  viewer.progress = info.progress;
  const bar = document.getElementById("timebar"), slider = document.getElementById("timeline");
  bar.className = "on";
  slider.min = info.first; slider.max = info.last; slider.value = info.first;
  document.getElementById("title").textContent = info.info.scenario_path || info.info.scenario_name || "";
  let inflight = false, wanted = null, playing = false, last = 0;
  async function show(tick) {
    wanted = tick;
    document.getElementById("tickshow").textContent = `tick ${tick}`;
    if (inflight) return;
    inflight = true;
    while (wanted !== null) {
      const t = wanted; wanted = null;
      const p = await (await fetch(`/api/frame?tick=${t}`)).json();
      draw(p);
      if (viewer.selectedAgent) await loadMaps();
    }
    inflight = false;
  }
  viewer.seek = (tick) => { slider.value = tick; return show(Number(slider.value)); };
  slider.addEventListener("input", () => show(Number(slider.value)));
  const button = document.getElementById("play");
  let pos = 0;
  button.onclick = () => { playing = !playing; button.textContent = playing ? "pause" : "play";
                           pos = Number(slider.value); last = performance.now(); if (playing) requestAnimationFrame(step); };
  function step(now) {
    if (!playing) return;
    pos = Math.min(pos + Number(document.getElementById("speed").value) * (now - last) / 1000, info.last);
    last = now;
    const t = Math.floor(pos);
    if (t !== Number(slider.value)) { slider.value = t; show(t); }
    if (pos >= info.last) { playing = false; button.textContent = "play"; return; }
    requestAnimationFrame(step);
  }
  await show(info.first);
}

fetch("/api/info").then(r => r.json()).then(info => {
  viewer.mode = info.mode;
  document.getElementById("mode").textContent = info.mode === "live" ? "live" : "recording";
  if (info.mode === "live") live(); else recording(info);
  const pick = /select=([A-Za-z0-9_.-]+)/.exec(location.hash);  // a link to one agent: page#select=a1
  if (pick) selectAgent(pick[1]);
});
