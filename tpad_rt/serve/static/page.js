// The page of `tpad-rt serve`: the plate with the texture's friction map, the finger, target and achieved
// friction, drive and power against their limits, live; pointer, pen and touch on the plate are the finger.
// It speaks the WebSocket protocol of docs/serve.md, as any other client does.

const PROTOCOL_VERSION = 1;
const TELEMETRY_HZ = 30;
const RESEND_MS = 25;          // a finger held still: its position again after this long (the renderer's
                               // watchdog ramps the drive down after 50 ms without a sample)
const HISTORY_S = 5;
const RECONNECT_MS = 1000;

const $ = (id) => document.getElementById(id);
const plate = $("plate");
const ctx = plate.getContext("2d");

// Everything the page knows; window.tpadPage exposes it (the tests read it, and so can a console).
const state = {
  connected: false, hello: null, device: null, texture: null, map: null, mapDrawn: 0, telemetry: null,
  finger: null, history: [], pressedPointer: null, lastPosition: null, lastT: 0, sent: 0, errors: [],
};
window.tpadPage = state;

const query = new URLSearchParams(location.search);
const token = query.get("token");
const wsUrl = `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws` +
  (token ? `?token=${encodeURIComponent(token)}` : "");
let socket = null;

function send(message) {
  if (socket && socket.readyState === WebSocket.OPEN) {
    socket.send(JSON.stringify(message));
    state.sent += 1;
  }
}

function log(text) {
  $("log").textContent = text;
}

function connect() {
  socket = new WebSocket(wsUrl);
  socket.addEventListener("open", () => {
    state.connected = true;
    $("connection").textContent = "connected";
    $("connection").className = "state-on";
  });
  socket.addEventListener("close", (event) => {
    state.connected = false;
    $("connection").textContent = `disconnected (${event.code}${event.reason ? ": " + event.reason : ""}); retrying`;
    $("connection").className = "state-off";
    setTimeout(connect, RECONNECT_MS);
  });
  socket.addEventListener("message", (event) => receive(JSON.parse(event.data)));
}

function receive(message) {
  switch (message.type) {
    case "hello":
      if (message.protocol !== PROTOCOL_VERSION) {
        log(`this page speaks protocol ${PROTOCOL_VERSION}, the server ${message.protocol}: reload the page`);
        socket.close();
        return;
      }
      state.hello = message;
      state.device = message.device;
      showDevice(message.device);
      fillTextures(message.textures, message.texture);
      showTexture(message.texture);
      state.finger = message.finger;
      showFinger();
      send({ type: "subscribe", rate_hz: TELEMETRY_HZ });
      break;
    case "texture":
      showTexture(message);
      break;
    case "telemetry":
      state.telemetry = message;
      state.history.push([message.t, message.target_mu, message.achieved_mu, message.touching]);
      while (state.history.length && state.history[0][0] < message.t - HISTORY_S) state.history.shift();
      showTelemetry(message);
      break;
    case "finger":
      state.finger = message;
      showFinger();
      break;
    case "error":
      state.errors.push(message);
      log(`${message.code}: ${message.message}`);
      break;
    default:
      break;
  }
}

function showDevice(device) {
  $("device").textContent = `${device.label}: ${device.plate.length_mm.toFixed(0)} × ` +
    `${device.plate.width_mm.toFixed(0)} mm, ${(device.carrier_hz / 1000).toFixed(2)} kHz, ` +
    `≤ ${device.max_voltage_v} V, ${device.power_budget_w} W budget, output ${device.output}`;
  plate.height = Math.round(plate.width * device.plate.width_mm / device.plate.length_mm);
}

function fillTextures(names, current) {
  const select = $("texture-select");
  select.replaceChildren();
  const here = document.createElement("option");
  here.value = "";
  here.textContent = `(${current.source})`;
  select.append(here);
  for (const name of names) {
    const option = document.createElement("option");
    option.value = option.textContent = name;
    select.append(option);
  }
}

$("texture-select").addEventListener("change", (event) => {
  if (event.target.value) send({ type: "texture", name: event.target.value });
});

function showTexture(texture) {
  state.texture = texture;
  $("texture-description").textContent = `${texture.description} (${texture.kind}, from ${texture.source})`;
  const image = new Image();
  image.addEventListener("load", () => {
    state.map = image;
    draw();
    state.mapDrawn += 1;
    document.body.dataset.map = texture.map;
  });
  image.src = texture.map;
}

function showFinger() {
  const finger = state.finger;
  if (!finger) return;
  $("finger-line").textContent = finger.yours ? "You have the finger." :
    finger.held ? `Another client (${finger.holder}) has the finger; it is yours once it lifts.` :
      "Press and slide on the plate: pointer, pen and touch are the finger.";
}

function draw() {
  ctx.imageSmoothingEnabled = false;
  if (state.map) ctx.drawImage(state.map, 0, 0, plate.width, plate.height);
  const t = state.telemetry;
  if (!t || !t.touching || !state.device) return;
  const x = t.x_mm / state.device.plate.length_mm * plate.width;
  const y = t.y_mm / state.device.plate.width_mm * plate.height;
  ctx.beginPath();
  ctx.arc(x, y, 9, 0, 2 * Math.PI);
  ctx.lineWidth = 3;
  ctx.strokeStyle = "#ffffff";
  ctx.stroke();
  ctx.lineWidth = 1.5;
  ctx.strokeStyle = "#e5534b";
  ctx.stroke();
}

function meter(bar, value, limit, limited) {
  bar.style.width = `${Math.min(100, 100 * value / limit)}%`;
  bar.classList.toggle("limited", limited);
}

function showTelemetry(t) {
  const device = state.device;
  $("finger-value").textContent = t.touching ?
    `${t.x_mm.toFixed(1)}, ${t.y_mm.toFixed(1)} mm, ${t.speed_mm_s.toFixed(0)} mm/s, ${t.force_n.toFixed(2)} N` : "off the plate";
  $("target-value").textContent = t.touching ? t.target_mu.toFixed(3) : "–";
  $("achieved-value").textContent = t.touching ? t.achieved_mu.toFixed(3) : "–";
  $("voltage-value").textContent = `${t.voltage_peak_v.toFixed(1)} V of ${device.max_voltage_v} V`;
  $("power-value").textContent = `${t.power_peak_w.toFixed(3)} W of ${device.power_budget_w} W`;
  meter($("voltage-bar"), t.voltage_peak_v, device.max_voltage_v, t.limited.voltage);
  meter($("power-bar"), t.power_peak_w, device.power_budget_w, t.limited.power);
  const held = [t.limited.voltage && "voltage", t.limited.power && "power", t.limited.fault && "fault guard"].filter(Boolean);
  $("limits-line").textContent = held.length ? `held by: ${held.join(", ")}` : "within the limits";
  draw();
  drawHistory();
}

function drawHistory() {
  const canvas = $("history");
  const g = canvas.getContext("2d");
  g.clearRect(0, 0, canvas.width, canvas.height);
  if (state.history.length < 2) return;
  const end = state.history[state.history.length - 1][0];
  const px = (t) => (t - end + HISTORY_S) / HISTORY_S * canvas.width;
  const py = (mu) => (1 - mu) * (canvas.height - 8) + 4;
  for (const [column, colour] of [[1, "#888888"], [2, "#f08c00"]]) {
    g.beginPath();
    let drawing = false;
    for (const row of state.history) {
      if (!row[3]) { drawing = false; continue; }
      if (drawing) g.lineTo(px(row[0]), py(row[column])); else g.moveTo(px(row[0]), py(row[column]));
      drawing = true;
    }
    g.strokeStyle = colour;
    g.lineWidth = 2;
    g.stroke();
  }
}

// --- the finger: pointer events (mouse, pen, touch) on the plate ---------------------------------

function platePosition(event) {
  const box = plate.getBoundingClientRect();
  const device = state.device;
  return [(event.clientX - box.left) / box.width * device.plate.length_mm,
    (event.clientY - box.top) / box.height * device.plate.width_mm];
}

// Samples are stamped with the page's clock (performance.now, seconds) when handled: an input event's own
// timeStamp can lag that by a frame or more (moves are dispatched once per frame), which would put it before a
// held-still resend. Coalesced events keep their spacing before the handled one; no time goes backwards.
function samples(events) {
  const now = performance.now() / 1000;
  const newest = events[events.length - 1].timeStamp / 1000;
  return events.map((event) => {
    const [x_mm, y_mm] = platePosition(event);
    state.lastPosition = [x_mm, y_mm];
    state.lastT = Math.max(now - (newest - event.timeStamp / 1000), state.lastT);
    return { x_mm, y_mm, t: state.lastT };
  });
}

plate.addEventListener("pointerdown", (event) => {
  if (!state.device || state.pressedPointer !== null) return;
  event.preventDefault();
  plate.setPointerCapture(event.pointerId);
  state.pressedPointer = event.pointerId;
  send({ type: "finger", ...samples([event])[0] });
});

plate.addEventListener("pointermove", (event) => {
  if (event.pointerId !== state.pressedPointer) return;
  const coalesced = event.getCoalescedEvents ? event.getCoalescedEvents() : [];
  const batch = samples(coalesced.length ? coalesced : [event]);
  send(batch.length === 1 ? { type: "finger", ...batch[0] } : { type: "fingers", samples: batch });
});

function release(event) {
  if (event.pointerId !== state.pressedPointer) return;
  state.pressedPointer = null;
  state.lastT = Math.max(performance.now() / 1000, state.lastT);
  send({ type: "lift", t: state.lastT });
}
plate.addEventListener("pointerup", release);
plate.addEventListener("pointercancel", release);
plate.addEventListener("lostpointercapture", release);

// A finger held still sends no events: send its position again once RESEND_MS passed without a sample.
setInterval(() => {
  const now = performance.now() / 1000;
  if (state.pressedPointer !== null && state.lastPosition && now - state.lastT >= RESEND_MS / 1000) {
    const [x_mm, y_mm] = state.lastPosition;
    state.lastT = now;
    send({ type: "finger", x_mm, y_mm, t: now });
  }
}, RESEND_MS / 5);

connect();
