// The zone editor: keepout and speed zones of UIConfig.zones_map drawn over the map. Everyone
// sees the zones; an operator draws a polygon (each click on the map is a corner), names it and
// saves it, edits one (a new polygon and/or value) or removes one. The server saves with the code
// `emos map zones MAP.yaml add/set/remove` uses, and refuses a viewer's edits whatever the page does.
"use strict";

function zoneEditor(map, operator) {
  const status = el("div", { id: "zone-status", class: "muted" });
  const list = el("div", { id: "zone-list" });
  const c = el("div", { class: "card", id: "zones" }, el("h2", {}, el("span", {}, "Zones"), el("span", { class: "type" }, "keepout · speed")), list);
  $("#inputs").append(c);
  const z = { zones: [], draft: [], drawing: false, editing: null };
  window.emosZones = z;  // for the tests

  const name = el("input", { id: "zone-name", placeholder: "name", maxlength: "64" });
  const kind = el("select", { id: "zone-kind" }, el("option", { value: "keepout" }, "keepout"), el("option", { value: "speed" }, "speed limit"));
  const value = el("input", { id: "zone-value", type: "number", step: "any", placeholder: "limit (% of max speed)" });
  const draw = el("button", { id: "zone-draw", class: "act secondary" }, "Draw on the map");
  const save = el("button", { id: "zone-save", class: "act" }, "Save zone");
  const cancel = el("button", { id: "zone-cancel", class: "act secondary" }, "Cancel");
  if (operator) {
    c.append(el("div", { class: "zone-form", "data-operator": "" }, name, kind, value, el("div", { class: "row" }, draw, save, cancel)));
  }
  c.append(status);
  const syncValue = () => { value.hidden = kind.value !== "speed"; };
  kind.addEventListener("change", syncValue);
  syncValue();

  function say(text, bad) { status.className = bad ? "error" : "muted"; status.textContent = text; }
  function reset() {
    z.draft = []; z.drawing = false; z.editing = null;
    name.value = ""; name.disabled = false; value.value = ""; kind.disabled = false;
    draw.textContent = "Draw on the map"; map.redraw();
  }

  // Each corner clicked while drawing goes to the draft, not to a goal.
  map.onClick = (x, y) => {
    if (!z.drawing) return false;
    z.draft.push([Math.round(x * 1000) / 1000, Math.round(y * 1000) / 1000]);
    say(`${z.draft.length} corner${z.draft.length > 1 ? "s" : ""}` + (z.draft.length < 3 ? ": at least 3" : ": Save zone when done"));
    return true;
  };
  map.overlays.push((ctx, toCanvas) => {
    const shape = (pts, fill, stroke, dashed) => {
      if (!pts.length) return;
      ctx.beginPath();
      pts.forEach(([x, y], i) => { const [cx, cy] = toCanvas(x, y); i ? ctx.lineTo(cx, cy) : ctx.moveTo(cx, cy); });
      if (pts.length > 2) ctx.closePath();
      ctx.fillStyle = fill; if (pts.length > 2) ctx.fill();
      ctx.setLineDash(dashed ? [6, 4] : []); ctx.strokeStyle = stroke; ctx.lineWidth = 2; ctx.stroke(); ctx.setLineDash([]);
    };
    for (const zone of z.zones) {
      if (z.editing === zone.name && z.draft.length) continue;
      shape(zone.polygon, zone.kind === "keepout" ? "rgba(239,68,82,0.30)" : "rgba(240,179,65,0.30)", zone.kind === "keepout" ? "#ef4452" : "#f0b341", false);
      const [cx, cy] = toCanvas(zone.polygon[0][0], zone.polygon[0][1]);
      ctx.fillStyle = "#fff"; ctx.font = "12px sans-serif";
      ctx.fillText(zone.kind === "speed" ? `${zone.name} ${zone.value}` : zone.name, cx + 3, cy - 3);
    }
    shape(z.draft, "rgba(78,161,255,0.25)", "#4ea1ff", true);
    for (const [x, y] of z.draft) { const [cx, cy] = toCanvas(x, y); ctx.fillStyle = "#4ea1ff"; ctx.fillRect(cx - 3, cy - 3, 6, 6); }
  });

  async function load() {
    const r = await fetch("/api/zones");
    const body = await r.json();
    if (!body.ok) { say(body.error, true); return; }
    z.zones = body.zones;
    const unit = body.speed_type === "speed_absolute" ? " m/s" : " %";
    list.replaceChildren(...(z.zones.length ? z.zones.map(zone => {
      const row = el("div", { class: "zone", "data-zone": zone.name },
        el("span", { class: "zone-name" }, zone.name), el("span", { class: "type" }, zone.kind === "speed" ? `speed ${zone.value}${unit}` : "keepout"));
      if (operator) {
        row.append(el("button", { class: "act secondary", "data-operator": "", "data-zone-edit": zone.name, onclick: () => {
          reset();
          z.editing = zone.name; z.draft = zone.polygon.map(p => p.slice());
          name.value = zone.name; name.disabled = true; kind.value = zone.kind; kind.disabled = true; syncValue();
          value.value = zone.kind === "speed" ? zone.value : "";
          say(`editing ${zone.name}: Draw on the map for a new outline, or change the limit, then Save zone`);
          map.redraw();
        } }, "Edit"),
        el("button", { class: "act secondary", "data-operator": "", "data-zone-remove": zone.name, onclick: () => send({ op: "remove", name: zone.name }) }, "Remove"));
      }
      return row;
    }) : [el("div", { class: "muted" }, "no zones")]));
    map.redraw();
  }

  async function send(edit) {
    const r = await postJSON("/api/zones", edit);
    let body;
    try { body = await r.json(); } catch (e) { body = { ok: false, error: `${r.status} ${await r.text()}` }; }
    if (!body.ok) { say(body.error, true); toast(body.error, false); return false; }
    toast(`zone ${edit.name}: ${edit.op === "remove" ? "removed" : "saved"}`, true);
    reset();
    say(`${edit.op === "remove" ? "removed" : "saved"} ${edit.name}`);
    await load();
    return true;
  }

  draw.addEventListener("click", () => {
    z.drawing = !z.drawing;
    if (z.drawing) { z.draft = []; say("click the corners of the zone on the map"); }
    draw.textContent = z.drawing ? "Drawing: click on the map" : "Draw on the map";
    map.redraw();
  });
  cancel.addEventListener("click", () => { reset(); say(""); });
  save.addEventListener("click", () => {
    const edit = { op: z.editing ? "set" : "add", name: (z.editing || name.value).trim() };
    if (!edit.name) { say("give the zone a name", true); return; }
    if (!z.editing) edit.kind = kind.value;
    if (z.draft.length && z.draft.length < 3) { say("a zone needs at least 3 corners", true); return; }
    if (z.draft.length >= 3) edit.polygon = z.draft;
    else if (!z.editing) { say("draw the zone on the map first (at least 3 corners)", true); return; }
    if (kind.value === "speed" && value.value !== "") edit.value = Number(value.value);
    send(edit);
  });
  load().catch(e => say(`cannot load the zones: ${e}`, true));
  return z;
}
