// The system graph (System tab): components, the topics they publish and subscribe, events (the
// topics they watch) and the actions they trigger. Three columns of an SVG, drawn from
// /api/v1/graph; nothing is loaded from elsewhere.
"use strict";

const SVG_NS = "http://www.w3.org/2000/svg";
function svg(tag, attrs = {}, text) {
  const node = document.createElementNS(SVG_NS, tag);
  for (const [k, v] of Object.entries(attrs)) if (v !== undefined && v !== null) node.setAttribute(k, v);
  if (text !== undefined) node.textContent = text;
  return node;
}

async function loadGraph() {
  const root = document.getElementById("system-graph");
  if (!root || root.dataset.loaded) return;
  let g;
  try {
    const res = await fetch("/api/v1/graph");
    g = await res.json();
  } catch (e) { root.textContent = `graph not available: ${e}`; return; }
  root.dataset.loaded = "1";
  drawGraph(root, g);
}

function drawGraph(root, g) {
  const rowH = 34, colX = [20, 330, 640], boxW = 240, top = 30;
  const cols = [g.components.map(c => ({ id: "component:" + c.name, label: c.name, sub: c.type, kind: "component" })),
    g.topics.map(t => ({ id: "topic:" + t.name, label: t.name, sub: t.type, kind: "topic" })),
    g.events.map(e => ({ id: "event:" + e.name, label: e.name, sub: e.actions.map(a => (a.component ? a.component + "." : "") + a.name).join(", "), kind: "event" }))];
  const pos = {};
  cols.forEach((nodes, c) => nodes.forEach((n, i) => { pos[n.id] = { x: colX[c], y: top + i * rowH, n }; }));
  const height = top + Math.max(1, ...cols.map(c => c.length)) * rowH + 10;
  const s = svg("svg", { viewBox: `0 0 ${colX[2] + boxW + 20} ${height}`, width: "100%", class: "graph", role: "img", "aria-label": "system graph" });
  const defs = svg("defs");
  for (const [id, color] of [["arrow-pub", "#4ea1ff"], ["arrow-sub", "#3ecf71"], ["arrow-evt", "#f0b341"]]) {
    const m = svg("marker", { id, viewBox: "0 0 10 10", refX: "10", refY: "5", markerWidth: "6", markerHeight: "6", orient: "auto-start-reverse" });
    m.append(svg("path", { d: "M 0 0 L 10 5 L 0 10 z", fill: color }));
    defs.append(m);
  }
  s.append(defs);
  ["components", "topics", "events and actions"].forEach((h, c) => s.append(svg("text", { x: colX[c], y: 16, class: "graph-head" }, h)));
  const edge = (from, to, kind, color, fromRight) => {
    const a = pos[from], b = pos[to];
    if (!a || !b) return;
    const x1 = fromRight ? a.x + boxW : a.x, y1 = a.y + 12, x2 = fromRight ? b.x : b.x + boxW, y2 = b.y + 12;
    s.append(svg("path", { d: `M ${x1} ${y1} C ${(x1 + x2) / 2} ${y1}, ${(x1 + x2) / 2} ${y2}, ${x2} ${y2}`, fill: "none", stroke: color,
      "stroke-width": "1.5", "marker-end": `url(#arrow-${kind})`, "data-edge": `${from}->${to}`, opacity: "0.8" }));
  };
  for (const c of g.components) {
    for (const t of c.publishes) edge("component:" + c.name, "topic:" + t, "pub", "#4ea1ff", true);
    for (const t of c.subscribes) edge("topic:" + t, "component:" + c.name, "sub", "#3ecf71", false);
  }
  for (const e of g.events) for (const t of e.topics) edge("topic:" + t, "event:" + e.name, "evt", "#f0b341", true);
  for (const p of Object.values(pos)) {
    const grp = svg("g", { "data-node": p.n.id, class: "node " + p.n.kind });
    grp.append(svg("rect", { x: p.x, y: p.y, width: boxW, height: 24, rx: p.n.kind === "topic" ? 12 : 5 }));
    grp.append(svg("text", { x: p.x + 8, y: p.y + 16 }, p.n.label + (p.n.sub ? `  · ${p.n.sub}` : "")));
    grp.append(svg("title", {}, `${p.n.kind} ${p.n.label}${p.n.sub ? " (" + p.n.sub + ")" : ""}`));
    s.append(grp);
  }
  root.replaceChildren(s);
}
