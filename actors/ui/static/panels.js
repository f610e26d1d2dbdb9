// The Settings and System tabs (loaded before app.js; uses its helpers at run time).
"use strict";

// ------------------------------------------------------------------ settings
async function loadSettings() {
  const root = $("#settings");
  const res = await fetch("/api/settings");
  const comps = await res.json();
  root.replaceChildren();
  if (!comps.length) root.append(el("div", { class: "muted" }, "no components"));
  for (const comp of comps) {
    const c = el("div", { class: "card", "data-component": comp.component }, el("h2", {}, el("span", {}, comp.component), el("span", { class: "type" }, comp.type)));
    const status = el("div", {});
    if (comp.error) status.append(el("div", { class: "error" }, comp.error));
    const inputs = {};
    for (const f of comp.fields) {
      const v = comp.values[f.name];
      let input;
      if (f.kind === "bool") { input = el("input", { type: "checkbox" }); input.checked = !!v; }
      else if (f.kind === "choice") { input = el("select", {}, ...f.choices.map(ch => el("option", { value: ch }, ch))); input.value = v; }
      else if (f.kind === "int" || f.kind === "float") {
        input = el("input", { type: "number", step: f.kind === "int" ? "1" : "any", value: v ?? "" });
      } else if (f.kind === "json") { input = el("input", { type: "text", value: JSON.stringify(v), disabled: "" }); }
      else input = el("input", { type: "text", value: v ?? "" });
      input.name = f.name;
      input.dataset.initial = f.kind === "bool" ? String(input.checked) : input.value;
      inputs[f.name] = { f, input };
      const row = el("div", { class: "field" }, el("label", { title: f.name }, f.name), input);
      const hint = [f.min !== undefined ? `range ${f.min} … ${f.max}` : "", f.help || "", f.editable ? "" : "set in config files"].filter(Boolean).join(" · ");
      if (hint) row.append(el("div", { class: "hint" }, hint));
      c.append(row);
    }
    const apply = el("button", { class: "act", "data-apply": comp.component, "data-operator": "" }, "Apply");
    apply.addEventListener("click", async () => {
      const values = {};
      for (const [name, { f, input }] of Object.entries(inputs)) {
        if (!f.editable) continue;
        const now = f.kind === "bool" ? String(input.checked) : input.value;
        if (now === input.dataset.initial) continue;
        values[name] = f.kind === "bool" ? input.checked : (f.kind === "int" || f.kind === "float") ? (input.value === "" ? null : Number(input.value)) : input.value;
      }
      status.replaceChildren();
      if (!Object.keys(values).length) { status.append(el("div", { class: "muted" }, "nothing changed")); return; }
      const r = await postJSON("/api/settings/" + encodeURIComponent(comp.component), values);
      const body = await r.json();
      if (body.ok) {
        for (const [name, { f, input }] of Object.entries(inputs)) {
          if (!(name in body.values) || !f.editable) continue;
          if (f.kind === "bool") input.checked = !!body.values[name]; else input.value = body.values[name];
          input.dataset.initial = f.kind === "bool" ? String(input.checked) : input.value;
        }
        status.append(el("div", { class: "okmsg" }, `applied: ${Object.keys(values).join(", ")}`));
      } else {
        for (const name of Object.keys(values)) { const { f, input } = inputs[name]; if (f.kind === "bool") input.checked = input.dataset.initial === "true"; else input.value = input.dataset.initial; }
        status.append(el("div", { class: "error" }, body.error));
      }
    });
    c.append(el("div", { class: "row" }, apply), status);
    root.append(c);
  }
}

// ------------------------------------------------------------------ system
function fmtUptime(s) { return s >= 3600 ? `${(s / 3600).toFixed(1)} h` : s >= 60 ? `${(s / 60).toFixed(1)} min` : `${s.toFixed(0)} s`; }

async function pollSystem() {
  if ($("#view-system").hidden) return;
  try {
    const res = await fetch("/api/system");
    const data = await res.json();
    const body = $("#system-table tbody");
    body.replaceChildren();
    if (data.error) { $("#system-meta").textContent = data.error; }
    else {
      $("#system-meta").textContent = `run ${data.run_id} · supervisor pid ${data.pid} · up ${fmtUptime(data.uptime_s)}`;
      const walk = (n, depth) => {
        const name = el("td", { style: `padding-left:${8 + depth * 18}px` }, n.name);
        if (n.kind === "supervisor") {
          body.append(el("tr", {}, name, el("td", { class: "sup", colspan: 3 }, `${n.strategy} · intensity ${n.intensity}`), el("td", {}, n.restarts ?? 0), el("td", { colspan: 4 })));
        } else {
          const buttons = el("td", {});
          for (const action of ["start", "stop", "restart"]) {
            if (n.name === data.ui && action !== "restart") continue;
            buttons.append(el("button", { class: "act secondary", "data-action": action, "data-component": n.name, "data-operator": "", onclick: async () => {
              const r = await postJSON(`/api/system/${encodeURIComponent(n.name)}/${action}`, {});
              const b = await r.json();
              b.ok ? toast(`${n.name}: ${b.detail}`, true) : toast(b.error, false);
              setTimeout(pollSystem, 300);
            } }, action));
          }
          body.append(el("tr", { "data-component": n.name }, name, el("td", {}, n.pid ?? "-"), el("td", {}, n.state ?? "?"),
            el("td", {}, el("span", { class: "health " + (n.health || "UNKNOWN") }, n.health || "UNKNOWN")), el("td", {}, n.restarts ?? 0),
            el("td", {}, n.uptime_s !== undefined ? fmtUptime(n.uptime_s) : "-"), el("td", {}, n.cpu_percent ?? "-"), el("td", {}, n.rss_mb ?? "-"), buttons));
        }
        for (const ch of n.children || []) walk(ch, depth + 1);
      };
      walk(data.tree, 0);
    }
  } catch (e) { $("#system-meta").textContent = `not reachable: ${e}`; }
  clearTimeout(pollSystem.timer);
  pollSystem.timer = setTimeout(pollSystem, 1000);
}

