// Microphone capture for Audio inputs (loaded before app.js).
"use strict";

// The microphone, recorded as 16 kHz mono 16-bit PCM (what Audio topics carry), sent as a WAV
// when the button is released. Browsers allow it on localhost or over HTTPS only.
function microphone(topic, button) {
  let ctx = null, stream = null, node = null, chunks = [], starting = false, released = false;
  async function start() {
    if (ctx || starting) return;
    if (!navigator.mediaDevices) { toast("the microphone needs HTTPS or localhost; upload a WAV instead", false); return; }
    starting = true; released = false;
    try {
      stream = await navigator.mediaDevices.getUserMedia({ audio: { channelCount: 1 } });
    } catch (e) { toast(`microphone: ${e.message}`, false); return; } finally { starting = false; }
    ctx = new AudioContext({ sampleRate: 16000 });
    const source = ctx.createMediaStreamSource(stream);
    node = ctx.createScriptProcessor(4096, 1, 1);
    chunks = [];
    node.onaudioprocess = ev => chunks.push(new Float32Array(ev.inputBuffer.getChannelData(0)));
    source.connect(node); node.connect(ctx.destination);
    button.textContent = "Recording... release to send";
    if (released) stop();  // the button was let go while the microphone was opening: send what there is
  }
  async function stop() {
    if (!ctx) { released = starting; return; }
    node.disconnect(); stream.getTracks().forEach(t => t.stop());
    const rate = ctx.sampleRate;
    await ctx.close(); ctx = null;
    button.textContent = "Hold to talk";
    const n = chunks.reduce((a, c) => a + c.length, 0);
    if (!n) return;
    const pcm = new Int16Array(n);
    let i = 0;
    for (const c of chunks) for (const v of c) pcm[i++] = Math.max(-32768, Math.min(32767, Math.round(v * 32767)));
    await uploadTo(topic, wav(pcm, rate));
  }
  return { start, stop };
}

function wav(pcm, rate) {
  const buf = new ArrayBuffer(44 + pcm.length * 2), v = new DataView(buf);
  const str = (o, s) => { for (let k = 0; k < s.length; k++) v.setUint8(o + k, s.charCodeAt(k)); };
  str(0, "RIFF"); v.setUint32(4, 36 + pcm.length * 2, true); str(8, "WAVEfmt "); v.setUint32(16, 16, true);
  v.setUint16(20, 1, true); v.setUint16(22, 1, true); v.setUint32(24, rate, true); v.setUint32(28, rate * 2, true);
  v.setUint16(32, 2, true); v.setUint16(34, 16, true); str(36, "data"); v.setUint32(40, pcm.length * 2, true);
  new Int16Array(buf, 44).set(pcm);
  return new Blob([buf], { type: "audio/wav" });
}

