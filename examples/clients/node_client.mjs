// A tpad-rt serve client in Node: set a texture, swipe a finger, watch it (what python_client.py does).
//
//   tpad-rt serve                         # in another terminal (any output)
//   node examples/clients/node_client.mjs [ws://127.0.0.1:8765/ws] [texture name]
//
// Node 22 and newer have the standard WebSocket; on Node 20 run it with --experimental-websocket.

import { TpadClient, TpadError } from "./tpad_client.js";

const url = process.argv[2] || "ws://127.0.0.1:8765/ws";
const textureName = process.argv[3] || "grating";
const SPEED_MM_S = 100;
const SAMPLE_PERIOD_S = 0.005;
const BATCH = 4;

if (typeof WebSocket === "undefined") {
  console.error("this Node has no WebSocket: use Node 22 or newer, or run node --experimental-websocket");
  process.exit(1);
}

const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, Math.max(0, ms)));
const now = () => performance.now() / 1000;
// A figure in ms to 0.01 ms, or "n/a" for none (the server sends null where nothing was measured).
const milliseconds = (value) => (value == null ? "n/a" : `${value.toFixed(2)} ms`);

async function main() {
  const tpad = await TpadClient.connect(url);
  const { device, texture, server } = tpad.hello;
  const plate = device.plate;
  console.log(`${server}: ${device.label}, plate ${plate.length_mm} x ${plate.width_mm} mm, at most ` +
    `${device.max_voltage_v} V; texture now: ${texture.description}`);

  const set = await tpad.texture({ name: textureName });
  console.log(`texture set: ${set.description}`);
  let errors = 0;
  tpad.on("error", (message) => { errors += 1; console.log(`  error ${message.code}: ${message.message}`); });
  tpad.on("telemetry", (m) => {
    if (m.touching) {
      console.log(`  x ${m.x_mm.toFixed(1).padStart(6)} mm  target ${m.target_mu.toFixed(3)}  achieved ` +
        `${m.achieved_mu.toFixed(3)}  drive ${m.voltage_peak_v.toFixed(1).padStart(5)} V  power ${m.power_peak_w.toFixed(3)} W`);
    }
  });
  await tpad.subscribe(20);

  // From x = 20 mm to 85 % of the plate and back at 100 mm/s, a sample every 5 ms, sent four at a time.
  const to = 0.85 * plate.length_mm;
  const steps = Math.floor((to - 20) / SPEED_MM_S / SAMPLE_PERIOD_S);
  const forth = Array.from({ length: steps + 1 }, (_, i) => 20 + (to - 20) * i / steps);
  const positions = forth.concat([...forth].reverse());
  const start = now();
  for (let first = 0; first < positions.length; first += BATCH) {
    await sleep((start + (first + BATCH - 1) * SAMPLE_PERIOD_S - now()) * 1000);
    tpad.fingers(positions.slice(first, first + BATCH).map((x_mm, i) => ({
      x_mm, y_mm: plate.width_mm / 2, t: start + (first + i) * SAMPLE_PERIOD_S,
    })));
  }
  tpad.lift(now());
  await sleep(200);
  const stats = (await tpad.stats()).renderer;
  console.log(`push-to-output latency p50 ${milliseconds(stats.latency_ms_p50)}, ` +
    `p99 ${milliseconds(stats.latency_ms_p99)}; ${errors} errors`);
  tpad.close();
  return errors ? 1 : 0;
}

main().then((status) => process.exit(status), (error) => {
  console.error(error instanceof TpadError ? `the server refused: ${error.message}` :
    `${url}: ${error.message} (is tpad-rt serve running?)`);
  process.exit(1);
});
