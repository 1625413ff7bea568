// hri view: polls the server (long polls, one request in flight per stream) and draws what it says.
// The overlay layers and colours are the same as hri/view/draw.py (the PNG snapshot).
"use strict";

const COLOURS = {
  box: "rgb(0,220,80)", target: "rgb(255,0,255)", candidate: "rgb(255,165,0)",
  hand: "rgb(0,255,255)", ray: "rgb(255,255,0)", person: "rgb(60,160,255)", speaker: "rgb(255,60,60)",
};
const HAND_CONNECTIONS = [[0, 1], [1, 2], [2, 3], [3, 4], [0, 5], [5, 6], [6, 7], [7, 8], [5, 9], [9, 10],
  [10, 11], [11, 12], [9, 13], [13, 14], [14, 15], [15, 16], [13, 17], [17, 18], [18, 19], [19, 20], [0, 17]];

// What tests and benchmarks read: frames drawn, frame delay (now - source stamp), page-side errors.
const view = window.hriView = { epoch: 0, version: -1, after: 0, state: null, cams: {}, timeline: new Map(),
  framesDrawn: 0, delays: [], pageErrors: 0, connected: false };

const $ = (id) => document.getElementById(id);

function el(tag, attrs, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (k === "class") node.className = v; else node.setAttribute(k, v);
  }
  for (const c of children) node.append(c instanceof Node ? c : String(c ?? ""));
  return node;
}

function num(x, digits = 2) { return typeof x === "number" && isFinite(x) ? x.toFixed(digits) : "?"; }

function clock(stamp) {
  if (typeof stamp !== "number") return "?";
  const d = new Date(stamp * 1000);
  return d.toLocaleTimeString([], { hour12: false }) + "." + String(d.getMilliseconds()).padStart(3, "0");
}

function objectName(o) { return [o.color, o.label].filter(Boolean).join(" "); }
// " (x, y, z) m" in the camera's optical frame when depth gave the object a position (as draw.py)
function signed(v) { return `${v >= 0 ? "+" : ""}${v.toFixed(2)}`; }
function objectPosition(o) {
  const p = o && o.position;
  return p ? ` (${signed(p[0])}, ${signed(p[1])}, ${p[2].toFixed(2)}) m` : "";
}

// -- layers (bottom to top), as in draw.py ------------------------------------------------------------
function drawLabel(ctx, text, x, y, colour) {
  ctx.font = "14px sans-serif";
  const w = ctx.measureText(text).width + 6, h = 18;
  const top = Math.max(y - h, 0);
  x = Math.max(0, Math.min(x, ctx.canvas.width - w));  // keep labels of objects at the right edge readable
  ctx.fillStyle = "black"; ctx.fillRect(x, top, w, h);
  ctx.fillStyle = colour; ctx.fillText(text, x + 3, top + 14);
}

function drawBox(ctx, bbox, colour, width, dash) {
  ctx.strokeStyle = colour; ctx.lineWidth = width; ctx.setLineDash(dash || []);
  ctx.strokeRect(bbox[0], bbox[1], bbox[2], bbox[3]);
  ctx.setLineDash([]);
}

function drawObjects(ctx, layers) {
  // the decision layer labels its own objects (target, candidates): no second label under theirs
  const decided = new Set([layers.target, ...(layers.candidates || [])].filter(Boolean).map((o) => o.id));
  for (const o of layers.objects || []) {
    drawBox(ctx, o.bbox, COLOURS.box, 2);
    if (!decided.has(o.id)) drawLabel(ctx, `${objectName(o)} ${o.id} ${num(o.score)}${objectPosition(o)}`, o.bbox[0], o.bbox[1], COLOURS.box);
  }
}

function drawRay(ctx, ray, length) {
  const [ox, oy] = ray.origin, [dx, dy] = ray.direction;
  ctx.strokeStyle = COLOURS.ray; ctx.lineWidth = 2;
  ctx.beginPath(); ctx.moveTo(ox, oy); ctx.lineTo(ox + dx * length, oy + dy * length); ctx.stroke();
}

function drawHands(ctx, layers) {
  const length = ctx.canvas.width + ctx.canvas.height;
  for (const hand of layers.hands || []) {
    const p = hand.landmarks;
    ctx.strokeStyle = COLOURS.hand; ctx.fillStyle = COLOURS.hand; ctx.lineWidth = 2;
    for (const [a, b] of HAND_CONNECTIONS) {
      ctx.beginPath(); ctx.moveTo(p[a][0], p[a][1]); ctx.lineTo(p[b][0], p[b][1]); ctx.stroke();
    }
    for (const q of p) { ctx.beginPath(); ctx.arc(q[0], q[1], 3, 0, 2 * Math.PI); ctx.fill(); }
    if (hand.ray) drawRay(ctx, hand.ray, length);
    if (hand.gesture) drawLabel(ctx, `${hand.hand} ${hand.gesture}`, p[0][0], p[0][1] + 20, COLOURS.hand);
  }
}

// Body skeletons and arm rays come here once the gesture service publishes them (a new layer).

function drawPersons(ctx, layers) {
  // each person's box and id; the speaker's thicker, in red, labelled as speaking (same as draw.py)
  for (const p of layers.persons || []) {
    const colour = p.speaker ? COLOURS.speaker : COLOURS.person;
    drawBox(ctx, p.bbox, colour, p.speaker ? 3 : 1);
    const hands = (p.hands || []).join(",");
    drawLabel(ctx, `${p.id}${p.speaker ? " speaking" : ""}${hands ? ` hands ${hands}` : ""}${objectPosition(p)}`,
      p.bbox[0], p.bbox[1] + 18, colour);
  }
}

function speakerText(s) {
  // who said it, as fusion attributed it (issue #33): "by person-2 (mouth_motion 0.87)" / "speaker unknown"
  if (!s) return "";
  return s.person ? ` · by ${s.person} (${s.method} ${num(s.confidence)})` : " · speaker unknown";
}

function drawDecision(ctx, layers) {
  for (const c of layers.candidates || []) {
    drawBox(ctx, c.bbox, COLOURS.candidate, 3, [8, 4]);
    drawLabel(ctx, `? ${objectName(c)} ${c.id}`, c.bbox[0], c.bbox[1], COLOURS.candidate);
  }
  const t = layers.target;
  if (t) {
    drawBox(ctx, t.bbox, COLOURS.target, 4);
    ctx.strokeStyle = COLOURS.target; ctx.lineWidth = 3;
    ctx.beginPath(); ctx.moveTo(t.center[0] - 9, t.center[1]); ctx.lineTo(t.center[0] + 9, t.center[1]);
    ctx.moveTo(t.center[0], t.center[1] - 9); ctx.lineTo(t.center[0], t.center[1] + 9); ctx.stroke();
    drawLabel(ctx, `${t.intent || "target"}: ${objectName(t)} ${t.id}${objectPosition(t)}`, t.bbox[0], t.bbox[1], COLOURS.target);
  }
  if (layers.location) {
    const { x, y } = layers.location;
    ctx.strokeStyle = COLOURS.target; ctx.lineWidth = 3;
    ctx.beginPath(); ctx.moveTo(x - 12, y - 12); ctx.lineTo(x + 12, y + 12); ctx.moveTo(x + 12, y - 12);
    ctx.lineTo(x - 12, y + 12); ctx.stroke();
  }
}

const LAYERS = [drawPersons, drawObjects, drawHands, drawDecision];
const DEPTH_ALPHA = 0.6;

function drawCamera(name) {
  const cam = view.cams[name];
  if (!cam || !cam.bitmap) return;
  const ctx = cam.canvas.getContext("2d");
  if (cam.canvas.width !== cam.bitmap.width) cam.canvas.width = cam.bitmap.width;
  if (cam.canvas.height !== cam.bitmap.height) cam.canvas.height = cam.bitmap.height;
  ctx.drawImage(cam.bitmap, 0, 0);
  if (cam.depthToggle.checked && cam.depthBitmap) {  // the depth overlay: near red, far blue, no depth black
    ctx.globalAlpha = DEPTH_ALPHA;
    ctx.drawImage(cam.depthBitmap, 0, 0, cam.canvas.width, cam.canvas.height);
    ctx.globalAlpha = 1;
  }
  const layers = (view.state && view.state.cameras[name]) || {};
  for (const layer of LAYERS) {
    try { layer(ctx, layers); } catch (err) { view.pageErrors++; console.warn("overlay", layer.name, err); }
  }
}

// -- cameras ------------------------------------------------------------------------------------------
function cameraPanel(name) {
  let cam = view.cams[name];
  if (cam) return cam;
  const canvas = el("canvas", { width: 640, height: 480, "data-cam": name });
  const meta = el("div", { class: "meta" });
  const depthToggle = el("input", { type: "checkbox", "data-depth": name });
  const depthLabel = el("label", { class: "depth-toggle", hidden: "" }, depthToggle, " depth");
  const panel = el("section", { class: "camera", id: `cam-${name}` }, el("h2", {}, name, " ", depthLabel), canvas,
    meta);
  const empty = $("cameras").querySelector(".empty");
  if (empty) empty.remove();
  $("cameras").append(panel);
  cam = view.cams[name] = { canvas, meta, panel, n: -1, bitmap: null, frames: 0, depthToggle, depthLabel,
    depthBitmap: null, depthSeq: null, depthLoading: false };
  depthToggle.addEventListener("change", () => {
    const info = view.state && view.state.cameras[name];
    if (info) updateDepth(name, info);
    drawCamera(name);
  });
  frameLoop(name);
  return cam;
}

async function frameLoop(name) {
  const cam = view.cams[name];
  for (;;) {
    try {
      const res = await fetch(`/api/frame/${encodeURIComponent(name)}?after=${cam.n}`, { cache: "no-store" });
      if (res.status === 200) {
        const stamp = parseFloat(res.headers.get("X-Stamp"));
        cam.n = parseInt(res.headers.get("X-Frame-N"), 10);
        const blob = await res.blob();
        try {
          const bitmap = await createImageBitmap(blob);
          if (cam.bitmap) cam.bitmap.close();
          cam.bitmap = bitmap;
          cam.frames++;
          drawCamera(name);
          view.framesDrawn++;
          view.delays.push(Date.now() / 1000 - stamp);
          if (view.delays.length > 300) view.delays.shift();
        } catch (err) {  // a JPEG that does not decode: skip it, keep the last good frame
          view.pageErrors++;
        }
      } else if (res.status !== 204) {
        await sleep(1000);
      }
    } catch (err) {
      await sleep(1000);
    }
  }
}

// The depth overlay: fetched only while its toggle is on, once per new depth frame.
async function updateDepth(name, info) {
  const cam = view.cams[name];
  cam.depthLabel.hidden = !info.depth;
  if (!info.depth || !cam.depthToggle.checked || cam.depthLoading || cam.depthSeq === info.depth.seq) return;
  cam.depthLoading = true;
  try {
    const res = await fetch(`/api/depth/${encodeURIComponent(name)}`, { cache: "no-store" });
    if (res.status === 200) {
      const bitmap = await createImageBitmap(await res.blob());
      if (cam.depthBitmap) cam.depthBitmap.close();
      cam.depthBitmap = bitmap;
      cam.depthSeq = parseInt(res.headers.get("X-Seq"), 10);
      drawCamera(name);
    }
  } catch (err) {
    view.pageErrors++;
  } finally {
    cam.depthLoading = false;
  }
}

function updateCameraMeta(name, info) {
  const cam = cameraPanel(name);
  updateDepth(name, info);
  const q = info.quality;
  const quality = q ? `brightness ${num(q.brightness)} · contrast ${num(q.contrast)} · sharpness ${num(q.sharpness)}`
    : "no detections yet";
  const frame = info.frame ? `${info.frame.width}×${info.frame.height}, seq ${info.frame.seq}` : "no frame";
  cam.meta.textContent = `${frame} · ${info.received} received, ${info.released} shown · ${quality}`;
  drawCamera(name);  // overlays move even when the frame does not
}

// -- timeline -----------------------------------------------------------------------------------------
function weightBars(weights) {
  const box = el("div", { class: "weights" });
  for (const [name, w] of Object.entries(weights || {})) {
    const pct = Math.max(0, Math.min(1, Number(w) || 0)) * 100;
    box.append(el("div", { class: "bar" }, el("span", {}, name),
      el("span", { class: "track" }, el("span", { class: "fill", style: `width:${pct.toFixed(0)}%` })),
      el("span", {}, num(w))));
  }
  return box;
}

function entryNode(e) {
  const time = el("time", {}, clock(e.t));
  const li = el("li", { class: e.kind, "data-n": e.n, "data-t": e.t });
  if (e.kind === "transcript") {
    li.append(time, el("span", { class: "kind" }, "heard"), `“${e.text}” `,
      el("small", {}, `confidence ${num(e.confidence)} · ${e.backend}`));
  } else if (e.kind === "gesture") {
    li.append(time, el("span", { class: "kind" }, "gesture"), `${e.gesture} (${e.hand} hand, ${e.cam}) `,
      el("small", {}, `score ${num(e.score)}`));
  } else if (e.kind === "command") {
    const t = e.target;
    const loc = e.location;
    const what = t ? ` → ${objectName(t)} ${t.id}${objectPosition(t)}`
      : (e.place ? ` → ${e.place}${objectPosition(loc)}` : "");
    const summary = el("summary", {}, time, el("span", { class: "kind" }, "command"),
      `${e.intent}${what} `, el("small", {}, `confidence ${num(e.confidence)}${speakerText(e.speaker)}`));
    const missing = Object.entries(e.inputs || {}).filter(([, s]) => s === null).map(([m]) => m);
    li.append(el("details", {}, summary,
      el("p", { class: "explanation" }, e.explanation),
      e.text ? el("p", {}, `said: “${e.text}”`) : "",
      e.motion ? el("p", {}, `motion: ${JSON.stringify(e.motion)}`) : "",
      weightBars(e.weights),
      missing.length ? el("p", { class: "dim" }, `missing: ${missing.join(", ")}`) : "",
      el("pre", { class: "prompt" }, e.prompt)));
  } else if (e.kind === "clarification") {
    const names = (e.candidates || []).map((c) => `${objectName(c)} ${c.id}`).join(", ");
    li.append(el("details", {}, el("summary", {}, time, el("span", { class: "kind" }, "question"),
      `${e.question} `, el("small", {}, `${e.reason}${speakerText(e.speaker)}`)),
      el("p", {}, `candidates: ${names || "none"}`), e.text ? el("p", {}, `said: “${e.text}”`) : ""));
  } else {
    li.append(time, el("span", { class: "kind" }, e.kind));
  }
  return li;
}

function addTimeline(entries) {
  const list = $("timeline");
  for (const e of entries) {
    if (view.timeline.has(e.n)) continue;
    let node;
    try { node = entryNode(e); } catch (err) { view.pageErrors++; continue; }
    view.timeline.set(e.n, node);
    // keep source-time order: entries may arrive late (a transcript ends after the gesture it names)
    const later = [...list.children].find((c) => Number(c.dataset.t) > e.t);
    list.insertBefore(node, later || null);
  }
  while (list.children.length > 500) { view.timeline.delete(Number(list.firstChild.dataset.n)); list.firstChild.remove(); }
  const last = list.lastElementChild;
  if (last && entries.length) last.scrollIntoView({ block: "nearest" });
}

// -- services -------------------------------------------------------------------------------------------
function updateServices(services) {
  const body = $("services").querySelector("tbody");
  body.replaceChildren(...services.map((s) => {
    const st = s.stats || {};
    const rejected = Object.values(st.rejected || {}).reduce((a, b) => a + b, 0);
    const live = s.alive === true ? el("span", { class: "good" }, "live")
      : s.alive === false ? el("span", { class: "bad" }, "gone") : el("span", { class: "dim" }, "seen");
    return el("tr", { "data-service": s.service }, el("td", {}, s.service), el("td", {}, s.instance),
      el("td", {}, live), el("td", {}, st.received ?? ""), el("td", {}, st.published ?? ""),
      el("td", {}, st.skipped ?? ""), el("td", { title: JSON.stringify(st.rejected || {}) }, s.stats ? rejected : ""),
      el("td", { class: "clocks" }, clockOffsets(st.other || {})),
      el("td", { class: "rates" }, stageRates(st.other || {})));
  }));
}

// the rates a service's stages run at (issue #42: `hri up`'s budget, docs/foundation.md) and what speech first eased
const RATE_GAUGES = [["max_rate_mhz", "model"], ["pose_max_rate_mhz", "pose"], ["faces_max_rate_mhz", "faces"]];
function stageRates(other) {
  const out = RATE_GAUGES.filter(([k]) => k in other && other[k] > 0)
    .map(([k, name]) => `${name} ≤ ${(other[k] / 1000).toFixed(1)} Hz`);
  if (other.persons_every) out.push(`persons every ${other.persons_every}`);
  if (other.eased_for_speech) out.push(`eased for speech ${other.eased_for_speech}`);
  return out.join(", ");
}

// fusion's estimate of each source's clock against its own (other["clock_offset_ms:SOURCE"]; docs/foundation.md)
function clockOffsets(other) {
  return Object.entries(other).filter(([k]) => k.startsWith("clock_offset_ms:"))
    .map(([k, ms]) => `${k.slice("clock_offset_ms:".length)} ${ms >= 0 ? "+" : ""}${ms} ms`).join(", ");
}

function updateIgnored(state) {
  $("ignored").textContent = `ignored: ${state.ignored_total}` + (view.pageErrors ? ` (+${view.pageErrors} in page)` : "");
  $("ignored").className = state.ignored_total ? "bad" : "";
  $("ignored-list").replaceChildren(...Object.entries(state.ignored).map(([key, reasons]) =>
    el("li", { class: "bad" }, `${key}: ${Object.entries(reasons).map(([r, n]) => `${r} ×${n}`).join(", ")}`)));
}

// -- recording player -----------------------------------------------------------------------------------
let dragging = false;

async function player(action, position) {
  try {
    await fetch("/api/player", { method: "POST", headers: { "Content-Type": "application/json" },
      body: JSON.stringify({ action, position }) });
  } catch (err) { view.pageErrors++; }
}

function setupPlayer() {
  $("play").addEventListener("click", () => player(view.state && view.state.player.playing ? "pause" : "play"));
  $("slider").addEventListener("input", () => { dragging = true; });
  $("slider").addEventListener("change", async () => { await player("seek", Number($("slider").value)); dragging = false; });
}

function updatePlayer(p) {
  $("player").hidden = false;
  $("play").textContent = p.playing ? "❚❚ pause" : "▶ play";
  $("slider").max = String(p.duration);
  if (!dragging) $("slider").value = String(p.position);
  $("position").textContent = `${num(p.position, 1)} / ${num(p.duration, 1)} s`;
}

// -- the state loop -------------------------------------------------------------------------------------
function sleep(ms) { return new Promise((r) => setTimeout(r, ms)); }

function apply(state) {
  if (state.epoch !== view.epoch) {  // a recording jumped back: start over
    view.timeline.clear(); $("timeline").replaceChildren();
    view.epoch = state.epoch;
  }
  view.version = state.version;
  view.state = state;
  $("mode").textContent = state.mode.label;
  const steps = [
    () => addTimeline(state.timeline),
    () => { for (const [name, info] of Object.entries(state.cameras)) updateCameraMeta(name, info); },
    () => updateServices(state.services),
    () => updateIgnored(state),
    () => { if (state.player) updatePlayer(state.player); },
  ];
  for (const step of steps) {
    try { step(); } catch (err) { view.pageErrors++; console.warn(err); }
  }
  for (const e of state.timeline) view.after = Math.max(view.after, e.n);
}

async function stateLoop() {
  for (;;) {
    const started = Date.now();
    try {
      const res = await fetch(`/api/state?epoch=${view.epoch}&version=${view.version}&after=${view.after}`,
        { cache: "no-store" });
      const state = await res.json();
      if (state.epoch !== view.epoch) view.after = 0;
      apply(state);
      view.connected = true;
      $("connection").textContent = "connected"; $("connection").className = "good";
    } catch (err) {
      view.connected = false;
      $("connection").textContent = "not connected (is hri view still running?)"; $("connection").className = "bad";
      await sleep(1000);
    }
    await sleep(Math.max(0, 100 - (Date.now() - started)));  // at most 10 state updates a second
  }
}

setupPlayer();
stateLoop();
