// The EMOS recipe page. Plain JavaScript, no framework, nothing loaded from elsewhere.
"use strict";

const $ = (sel, root = document) => root.querySelector(sel);
const el = (tag, attrs = {}, ...children) => {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "class") node.className = v;
    else if (k === "style") node.style.cssText = v;  // through the CSSOM: the page's CSP forbids style attributes
    else if (k.startsWith("on")) node.addEventListener(k.slice(2), v);
    else if (v !== undefined && v !== null) node.setAttribute(k, v);
  }
  for (const c of children) node.append(c instanceof Node ? c : document.createTextNode(String(c)));
  return node;
};

// This session's CSRF token, put in the page by the server (only pages of this origin can read
// it): every POST carries it in X-EMOS-CSRF, the websocket in its address.
const CSRF = document.querySelector('meta[name="emos-csrf"]').content;

function postJSON(url, value) {
  return fetch(url, { method: "POST", headers: { "Content-Type": "application/json", "X-EMOS-CSRF": CSRF }, body: JSON.stringify(value) });
}

// Measurements the benchmark and the tests read.
window.emosStats = { frames: {}, latencies: [], messages: 0, connects: 0, published: [] };

const state = { layout: null, ws: null, widgets: {}, map: null, requests: new Map(), nextId: 1, actions: new Map() };

function toast(text, good) {
  const t = $("#toast");
  t.textContent = text;
  t.className = "toast " + (good ? "good" : "bad");
  t.hidden = false;
  clearTimeout(toast.timer);
  toast.timer = setTimeout(() => { t.hidden = true; }, good ? 2000 : 6000);
}

// ------------------------------------------------------------------ tabs
for (const tab of document.querySelectorAll(".tab")) {
  tab.addEventListener("click", () => {
    for (const t of document.querySelectorAll(".tab")) t.classList.toggle("active", t === tab);
    for (const v of document.querySelectorAll(".view")) v.hidden = v.id !== "view-" + tab.dataset.view;
    if (tab.dataset.view === "settings") loadSettings();
    if (tab.dataset.view === "system") { pollSystem(); loadGraph(); }
  });
}

// ------------------------------------------------------------------ output widgets
function card(title, type) {
  const c = el("div", { class: "card" }, el("h2", {}, el("span", {}, title), el("span", { class: "type" }, type)));
  $("#outputs").append(c);
  return c;
}

function imageWidget(out) {
  const c = card(out.topic, out.type);
  const canvas = el("canvas", { width: 640, height: 480, "data-topic": out.topic, class: "image" });
  const info = el("div", { class: "muted" }, "waiting for the first frame");
  c.append(canvas, info);
  const ctx = canvas.getContext("2d");
  let shown = 0, since = performance.now();
  return {
    async frame(h, blob) {
      try {
        const bmp = await createImageBitmap(blob);
        if (canvas.width !== bmp.width || canvas.height !== bmp.height) { canvas.width = bmp.width; canvas.height = bmp.height; }
        ctx.drawImage(bmp, 0, 0);
        if (h.boxes) drawBoxes(ctx, h.boxes, h.width ? bmp.width / h.width : 1);
        bmp.close();
      } finally { ack(h.topic); }
      recordFrame(h);
      shown++;
      const now = performance.now();
      if (now - since > 1000) {
        info.textContent = `${canvas.width}x${canvas.height}  ${(shown * 1000 / (now - since)).toFixed(1)} fps shown`;
        shown = 0; since = now;
      }
    },
  };
}

function drawBoxes(ctx, boxes, scale) {
  ctx.lineWidth = 2; ctx.font = "14px system-ui"; ctx.strokeStyle = "#3ecf71"; ctx.fillStyle = "#3ecf71";
  for (const [x1, y1, x2, y2, label, score] of boxes) {
    ctx.strokeRect(x1 * scale, y1 * scale, (x2 - x1) * scale, (y2 - y1) * scale);
    ctx.fillText(`${label} ${score.toFixed(2)}`, x1 * scale + 3, Math.max(14, y1 * scale - 4));
  }
}

function recordFrame(h) {
  const s = window.emosStats;
  s.frames[h.topic] = (s.frames[h.topic] || 0) + 1;
  s.latencies.push(Date.now() - h.stamp);
  if (s.latencies.length > 5000) s.latencies.splice(0, 1000);
}

function audioWidget(out) {
  const c = card(out.topic, out.type);
  const player = el("audio", { controls: "" });
  c.append(player);
  let url = null;
  return {
    frame(h, blob) {
      if (url) URL.revokeObjectURL(url);
      url = URL.createObjectURL(blob);
      player.src = url;
      player.play().catch(() => {});
      ack(h.topic);
      recordFrame(h);
    },
  };
}

function logWidget(out) {
  const c = card(out.topic, out.type);
  const list = el("div", { class: "log", "data-topic": out.topic }, el("div", { class: "muted" }, "no messages yet"));
  c.append(list);
  let empty = true;
  let open = null;  // the bubble a streamed reply is still being written into
  return {
    log(msg) {
      if (empty) { list.replaceChildren(); empty = false; }
      if (msg.missed) { list.append(el("div", { class: "muted" }, `... ${msg.missed} messages skipped`)); open = null; }
      for (const [, stamp, value] of msg.items) {
        if (value !== null && typeof value === "object") {  // StreamingString chunk
          if (!open) { open = el("div", { class: "bubble" }, el("span", { class: "t" }, new Date(stamp).toLocaleTimeString()), ""); list.append(open); }
          open.append(document.createTextNode(value.text));
          if (value.done || !value.stream) open = null;
          continue;
        }
        list.append(el("div", { class: "bubble" }, el("span", { class: "t" }, new Date(stamp).toLocaleTimeString()), String(value)));
      }
      while (list.childElementCount > 200) list.firstElementChild.remove();
      list.scrollTop = list.scrollHeight;
    },
  };
}

function plotWidget(out) {
  const c = card(out.topic, out.type);
  const value = el("div", { class: "value", "data-topic": out.topic }, "-");
  const canvas = el("canvas", { width: 600, height: 160, class: "plot" });
  c.append(value, canvas);
  const points = [];
  const ctx = canvas.getContext("2d");
  let pending = false;
  function draw() {
    pending = false;
    const W = canvas.width, H = canvas.height, now = Date.now(), span = 60000;
    ctx.clearRect(0, 0, W, H);
    while (points.length && points[0][0] < now - span) points.shift();
    if (!points.length) return;
    let lo = Infinity, hi = -Infinity;
    for (const [, v] of points) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
    if (hi - lo < 1e-9) { hi += 1; lo -= 1; }
    ctx.strokeStyle = "#33333d"; ctx.fillStyle = "#9a9aa8"; ctx.font = "11px system-ui";
    ctx.fillText(hi.toPrecision(4), 4, 12); ctx.fillText(lo.toPrecision(4), 4, H - 4);
    ctx.strokeStyle = "#4ea1ff"; ctx.lineWidth = 2; ctx.beginPath();
    points.forEach(([t, v], i) => {
      const x = W - (now - t) / span * W, y = H - 6 - (v - lo) / (hi - lo) * (H - 18);
      i ? ctx.lineTo(x, y) : ctx.moveTo(x, y);
    });
    ctx.stroke();
  }
  return {
    log(msg) {
      for (const [, stamp, v] of msg.items) points.push([stamp, v]);
      const last = msg.items[msg.items.length - 1];
      if (last) value.textContent = Number(last[2]).toPrecision(6).replace(/\.?0+$/, "");
      if (!pending) { pending = true; requestAnimationFrame(draw); }
    },
  };
}

function latestWidget(out) {
  const c = card(out.topic, out.type);
  const body = out.kind === "bool" ? el("div", { class: "value", "data-topic": out.topic }, "-") : el("pre", { class: "msg", "data-topic": out.topic }, "waiting for a message");
  c.append(body);
  return {
    latest(msg) {
      const v = msg.value;
      if (out.kind === "bool") body.textContent = v ? "true" : "false";
      else if (out.kind === "pose" && v) body.textContent = `x ${v.x.toFixed(3)} m   y ${v.y.toFixed(3)} m   yaw ${(v.yaw * 180 / Math.PI).toFixed(1)}°`;
      else if (out.kind === "path") body.textContent = `${v.length} points` + (v.length ? `, to (${v[v.length - 1][0].toFixed(2)}, ${v[v.length - 1][1].toFixed(2)})` : "");
      else body.textContent = JSON.stringify(v, null, 2);
    },
  };
}

// ------------------------------------------------------------------ the map view
// Grids are drawn north up; one screen pixel maps back to world metres through the base map's
// origin and resolution, which is how a click becomes a goal.
function mapWidget(outs, goalInputs) {
  const c = card("Map", outs.map(o => o.topic).join(" · "));
  const canvas = el("canvas", { width: 640, height: 480, class: "map", id: "map-canvas" });
  const legend = el("div", { class: "legend" });
  const info = el("div", { class: "muted" }, goalInputs.length ? `click on the map to send a goal to ${goalInputs[0].topic}` : "waiting for the map");
  c.append(canvas, legend, info);
  const colors = ["#4ea1ff", "#3ecf71", "#f0b341", "#c77dff", "#ff7aa2"];
  const layers = {}, poses = {}, paths = {};
  let goal = null, pending = false, colorIndex = 0;
  const colorOf = {};
  for (const o of outs) {
    if (o.kind !== "map") { colorOf[o.topic] = colors[colorIndex++ % colors.length]; legend.append(el("span", {}, el("i", { style: `background:${colorOf[o.topic]}` }), o.topic)); }
  }
  const ctx = canvas.getContext("2d");
  let view = null;  // {s, offX, offY, base}

  function base() { return Object.values(layers).find(l => !l.h.overlay) || Object.values(layers)[0]; }
  function layout() {
    const b = base();
    if (!b) return null;
    const W = canvas.width, H = canvas.height;
    const s = Math.min(W / b.h.width, H / b.h.height);
    return { s, offX: (W - b.h.width * s) / 2, offY: (H - b.h.height * s) / 2, b };
  }
  function toCanvas(x, y) {
    const { s, offX, offY, b } = view, r = b.h.resolution, [ox, oy] = b.h.origin;
    return [offX + (x - ox) / r * s, offY + (b.h.height - (y - oy) / r) * s];
  }
  function toWorld(cx, cy) {
    const { s, offX, offY, b } = view, r = b.h.resolution, [ox, oy] = b.h.origin;
    return [ox + (cx - offX) / s * r, oy + (b.h.height - (cy - offY) / s) * r];
  }
  function draw() {
    pending = false;
    view = layout();
    ctx.fillStyle = "#0b0b0f"; ctx.fillRect(0, 0, canvas.width, canvas.height);
    if (!view) return;
    ctx.imageSmoothingEnabled = false;
    const b = view.b;
    ctx.drawImage(b.bmp, view.offX, view.offY, b.h.width * view.s, b.h.height * view.s);
    for (const l of Object.values(layers)) {
      if (l === b) continue;
      const r = l.h.resolution, [ox, oy] = l.h.origin;
      const [x0, y1] = toCanvas(ox, oy + l.h.height * r), [x1, y0] = toCanvas(ox + l.h.width * r, oy);
      ctx.globalAlpha = 0.85; ctx.drawImage(l.bmp, x0, y1, x1 - x0, y0 - y1); ctx.globalAlpha = 1;
    }
    for (const [topic, pts] of Object.entries(paths)) {
      ctx.strokeStyle = colorOf[topic]; ctx.lineWidth = 2; ctx.beginPath();
      pts.forEach(([x, y], i) => { const [cx, cy] = toCanvas(x, y); i ? ctx.lineTo(cx, cy) : ctx.moveTo(cx, cy); });
      ctx.stroke();
    }
    for (const [topic, p] of Object.entries(poses)) {
      const [cx, cy] = toCanvas(p.x, p.y), L = 14;
      ctx.save(); ctx.translate(cx, cy); ctx.rotate(-p.yaw);
      ctx.fillStyle = colorOf[topic]; ctx.beginPath(); ctx.moveTo(L, 0); ctx.lineTo(-L * 0.6, L * 0.55); ctx.lineTo(-L * 0.3, 0); ctx.lineTo(-L * 0.6, -L * 0.55); ctx.closePath(); ctx.fill();
      ctx.restore();
    }
    if (goal) {
      const [cx, cy] = toCanvas(goal[0], goal[1]);
      ctx.strokeStyle = "#ef4452"; ctx.lineWidth = 3; ctx.beginPath(); ctx.arc(cx, cy, 7, 0, 2 * Math.PI); ctx.stroke();
    }
    for (const overlay of api.overlays) overlay(ctx, toCanvas);  // e.g. the zone editor's polygons
  }
  function redraw() { if (!pending) { pending = true; requestAnimationFrame(draw); } }
  canvas.addEventListener("click", ev => {
    if (!view) return;
    const rect = canvas.getBoundingClientRect();
    const cx = (ev.clientX - rect.left) * canvas.width / rect.width, cy = (ev.clientY - rect.top) * canvas.height / rect.height;
    const [x, y] = toWorld(cx, cy);
    if (api.onClick && api.onClick(x, y)) { redraw(); return; }  // taken (the zone editor while drawing)
    if (!goalInputs.length) return;
    goal = [x, y];
    const target = $("#goal-target") ? $("#goal-target").value : goalInputs[0].topic;
    sendInput(target, { x, y }).then(ok => { if (ok) info.textContent = `goal (${x.toFixed(2)}, ${y.toFixed(2)}) sent to ${target}`; });
    redraw();
  });
  const api = {
    overlays: [], onClick: null, redraw, canvas,
    async frame(h, blob) {
      try {
        const bmp = await createImageBitmap(blob);
        if (layers[h.topic]) layers[h.topic].bmp.close();
        layers[h.topic] = { h, bmp };
        if (!goalInputs.length) info.textContent = `${h.width}x${h.height} cells at ${h.resolution.toFixed(3)} m`;
      } finally { ack(h.topic); }
      recordFrame(h);
      redraw();
    },
    latest(msg) {
      if (msg.kind === "pose" && msg.value) poses[msg.topic] = msg.value;
      if (msg.kind === "path") paths[msg.topic] = msg.value;
      redraw();
    },
    toWorld: (cx, cy) => (view ? toWorld(cx, cy) : null),
    toCanvas: (x, y) => (view ? toCanvas(x, y) : null),
  };
  return api;
}

// ------------------------------------------------------------------ inputs
function inputCard(inp) {
  const c = el("div", { class: "card", "data-input": inp.topic }, el("h2", {}, el("span", {}, inp.topic), el("span", { class: "type" }, inp.type)));
  $("#inputs").append(c);
  return c;
}

async function sendInput(topic, value) {
  const id = state.nextId++;
  if (!state.ws || state.ws.readyState !== WebSocket.OPEN) { toast("not connected to the robot", false); return false; }
  const done = new Promise(resolve => state.requests.set(id, resolve));
  const op = state.actions.has(topic) ? "goal" : "publish";
  state.ws.send(JSON.stringify({ op, id, topic, value }));
  const res = await done;
  window.emosStats.published.push({ topic, ok: res.ok, error: res.error });
  if (!res.ok) toast(res.error, false);
  return res.ok;
}

function buildInput(inp, hasMap) {
  const c = inputCard(inp);
  if (inp.kind === "text") {
    const box = el("textarea", { placeholder: "type and press Enter", "data-topic": inp.topic });
    const send = async () => { if (box.value.trim() && await sendInput(inp.topic, box.value)) box.value = ""; };
    box.addEventListener("keydown", ev => { if (ev.key === "Enter" && !ev.shiftKey) { ev.preventDefault(); send(); } });
    c.append(box, el("div", { class: "row" }, el("button", { class: "act", onclick: send }, "Send")));
  } else if (inp.kind === "bool") {
    c.append(el("div", { class: "row" },
      el("button", { class: "act", "data-value": "true", onclick: () => sendInput(inp.topic, true) }, "True"),
      el("button", { class: "act secondary", "data-value": "false", onclick: () => sendInput(inp.topic, false) }, "False")));
  } else if (inp.kind === "number") {
    const box = el("input", { type: "number", step: "any", value: "0" });
    c.append(box, el("div", { class: "row" }, el("button", { class: "act", onclick: () => sendInput(inp.topic, Number(box.value)) }, "Send")));
  } else if (inp.kind === "action") {
    const status = el("div", { class: "muted", "data-action-status": inp.topic }, "no goal sent yet");
    state.actions.set(inp.topic, status);
    if (inp.click) {
      const x = el("input", { type: "number", step: "any", placeholder: "x (m)" }), y = el("input", { type: "number", step: "any", placeholder: "y (m)" });
      c.append(el("div", { class: "muted" }, hasMap ? "Click on the map, or enter a goal:" : "Enter a goal in map coordinates:"),
        el("div", { class: "row" }, x, y),
        el("div", { class: "row" }, el("button", { class: "act", "data-send": inp.topic, onclick: () => sendInput(inp.topic, { x: Number(x.value), y: Number(y.value) }) }, "Send goal"),
          el("button", { class: "act secondary", onclick: () => cancelGoal(inp.topic) }, "Cancel")));
    } else {
      const initial = {};
      for (const f of inp.fields || []) if (f.default !== undefined) initial[f.name] = f.default;
      const box = el("textarea", { rows: 6 });
      box.value = JSON.stringify(initial, null, 1);
      c.append(box, el("div", { class: "row" }, el("button", { class: "act", onclick: () => {
        let v; try { v = JSON.parse(box.value); } catch (e) { toast(`${inp.topic}: not valid JSON (${e.message})`, false); return; }
        sendInput(inp.topic, v);
      } }, "Send goal"), el("button", { class: "act secondary", onclick: () => cancelGoal(inp.topic) }, "Cancel")));
    }
    c.append(status);
  } else if (inp.kind === "goal") {
    const x = el("input", { type: "number", step: "any", placeholder: "x (m)" }), y = el("input", { type: "number", step: "any", placeholder: "y (m)" });
    c.append(el("div", { class: "muted" }, hasMap ? "Click on the map, or enter a goal:" : "Enter a goal in map coordinates:"),
      el("div", { class: "row" }, x, y),
      el("div", { class: "row" }, el("button", { class: "act", onclick: () => sendInput(inp.topic, { x: Number(x.value), y: Number(y.value) }) }, "Send goal")));
  } else if (inp.kind === "audio" || inp.kind === "image") {
    const file = el("input", { type: "file", accept: inp.kind === "audio" ? "audio/wav" : "image/*" });
    const upload = async () => {
      if (!file.files.length) return;
      await uploadTo(inp.topic, file.files[0]);
    };
    c.append(el("div", { class: "muted" }, inp.kind === "audio" ? "WAV, 16 kHz mono 16-bit" : "a picture file"), file,
      el("div", { class: "row" }, el("button", { class: "act", onclick: upload }, "Upload")));
    if (inp.kind === "audio") {
      const rec = el("button", { class: "act secondary", "data-record": inp.topic }, "Hold to talk");
      const mic = microphone(inp.topic, rec);
      rec.addEventListener("pointerdown", mic.start);
      for (const ev of ["pointerup", "pointerleave"]) rec.addEventListener(ev, mic.stop);
      c.append(el("div", { class: "row" }, rec));
    }
  } else {
    const initial = {};
    for (const f of inp.fields || []) if (f.default !== undefined) initial[f.name] = f.default;
    const box = el("textarea", { rows: 6 });
    box.value = JSON.stringify(initial, null, 1);
    c.append(box, el("div", { class: "row" }, el("button", { class: "act", onclick: () => {
      let v; try { v = JSON.parse(box.value); } catch (e) { toast(`${inp.topic}: not valid JSON (${e.message})`, false); return; }
      sendInput(inp.topic, v).then(ok => ok && toast(`sent to ${inp.topic}`, true));
    } }, "Send")));
  }
}

async function cancelGoal(topic) {
  const id = state.nextId++;
  if (!state.ws || state.ws.readyState !== WebSocket.OPEN) return;
  const done = new Promise(resolve => state.requests.set(id, resolve));
  state.ws.send(JSON.stringify({ op: "cancel", id, topic }));
  const res = await done;
  if (!res.ok) toast(res.error, false);
}

async function uploadTo(topic, blob) {
  const res = await fetch("/api/upload" + (topic.startsWith("/") ? topic : "/" + topic), { method: "POST", headers: { "X-EMOS-CSRF": CSRF }, body: blob });
  const body = await res.json();
  window.emosStats.published.push({ topic, ok: body.ok, error: body.error });
  body.ok ? toast(`sent to ${topic}`, true) : toast(body.error, false);
  return body.ok;
}

// ------------------------------------------------------------------ connection
function ack(topic) { if (state.ws && state.ws.readyState === WebSocket.OPEN) state.ws.send(JSON.stringify({ op: "ack", topic })); }

function connect() {
  const ws = new WebSocket((location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/ws?csrf=" + encodeURIComponent(CSRF));
  ws.binaryType = "arraybuffer";
  state.ws = ws;
  ws.onopen = () => { $("#conn-dot").className = "dot on"; $("#conn-text").textContent = "live"; window.emosStats.connects++; connect.delay = 250; };
  ws.onclose = () => {
    $("#conn-dot").className = "dot off"; $("#conn-text").textContent = "reconnecting";
    for (const resolve of state.requests.values()) resolve({ ok: false, error: "connection lost" });
    state.requests.clear();
    connect.delay = Math.min((connect.delay || 250) * 2, 3000);
    setTimeout(connect, connect.delay);
  };
  ws.onmessage = ev => {
    window.emosStats.messages++;
    if (typeof ev.data === "string") {
      const msg = JSON.parse(ev.data);
      if (msg.op === "result") { const r = state.requests.get(msg.id); state.requests.delete(msg.id); if (r) r(msg); return; }
      if (msg.op === "error") { toast(msg.error, false); return; }
      if (msg.op === "action") {
        const status = state.actions.get(msg.topic);
        if (status) { status.textContent = `${msg.state}: ${typeof msg.value === "string" ? msg.value : JSON.stringify(msg.value)}`; status.dataset.state = msg.state; }
        return;
      }
      const w = state.widgets[msg.topic];
      if (!w) return;
      if (msg.op === "log") w.log(msg); else if (msg.op === "latest") w.latest(msg);
      return;
    }
    const view = new DataView(ev.data), n = view.getUint32(0);
    const h = JSON.parse(new TextDecoder().decode(new Uint8Array(ev.data, 4, n)));
    const w = state.widgets[h.topic];
    if (!w) { ack(h.topic); return; }
    w.frame(h, new Blob([new Uint8Array(ev.data, 4 + n)], { type: h.mime }));
  };
}

// ------------------------------------------------------------------ start
async function start() {
  // Who we are: a viewer watches only (the server refuses its changes anyway; the page just
  // does not offer them).
  const me = await (await fetch("/api/session")).json();
  state.role = me.role;
  $("#role").textContent = me.role + (me.name ? ` · ${me.name}` : "");
  document.body.classList.toggle("role-viewer", me.role !== "operator");
  const res = await fetch("/api/layout");
  const layout = await res.json();
  if (state.role !== "operator") layout.inputs = [];
  state.layout = layout;
  document.title = layout.title;
  $("#title").textContent = layout.title.replace(/^EMOS\s*·?\s*/, "");
  const goalInputs = layout.inputs.filter(i => i.kind === "goal" || (i.kind === "action" && i.click));
  const mapOuts = layout.outputs.filter(o => ["map", "pose", "path"].includes(o.kind));
  const hasMap = mapOuts.some(o => o.kind === "map");
  if (hasMap) {
    const w = mapWidget(mapOuts, goalInputs);
    state.map = w;
    for (const o of mapOuts) state.widgets[o.topic] = w;
  }
  for (const out of layout.outputs) {
    if (hasMap && ["map", "pose", "path"].includes(out.kind)) continue;
    const make = { image: imageWidget, audio: audioWidget, text: logWidget, number: plotWidget }[out.kind] || latestWidget;
    state.widgets[out.topic] = make(out);
  }
  if (goalInputs.length > 1 && hasMap) {
    const c = el("div", { class: "card" }, el("h2", {}, "Map clicks go to"), el("select", { id: "goal-target" }, ...goalInputs.map(g => el("option", { value: g.topic }, g.topic))));
    $("#inputs").append(c);
  }
  for (const inp of layout.inputs) buildInput(inp, hasMap);
  if (layout.zones && hasMap) zoneEditor(state.map, state.role === "operator");  // zones.js
  connect();
}

start().catch(e => toast(`cannot load the page layout: ${e}`, false));
