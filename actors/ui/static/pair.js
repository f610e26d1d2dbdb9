// The pairing page: the code (typed, or from the QR code's address: /pair#code=...) buys this
// browser a device token, which the server sets as an HttpOnly cookie; then on to the page.
"use strict";

(function () {
  const form = document.getElementById("pair-form"), status = document.getElementById("pair-status");
  const fromLink = new URLSearchParams(location.hash.slice(1)).get("code");
  if (fromLink) {
    document.getElementById("pair-code").value = fromLink;
    history.replaceState(null, "", "/pair");  // the code out of the address bar and the history
  }
  form.addEventListener("submit", async ev => {
    ev.preventDefault();
    status.className = "muted"; status.textContent = "pairing...";
    const body = { code: form.code.value, role: form.role.value };
    if (form.name.value.trim()) body.name = form.name.value.trim();
    try {
      const r = await fetch("/api/pair", { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body) });
      const answer = await r.json();
      if (answer.ok) {
        status.className = "okmsg"; status.textContent = `paired as ${answer.device.role}`;
        window.emosPaired = answer.device;
        location.href = "/";
      } else { status.className = "error"; status.textContent = answer.error; }
    } catch (e) { status.className = "error"; status.textContent = `cannot pair: ${e}`; }
  });
})();
