// A small client of tpad-rt serve's WebSocket API (docs/serve.md), for the browser and Node (an ES module
// on the standard WebSocket: browsers, Node 22 and newer, or Node 20 with --experimental-websocket).
//
//   import { TpadClient } from "./tpad_client.js";
//   const tpad = await TpadClient.connect("ws://127.0.0.1:8765/ws");
//   await tpad.texture({ name: "grating" });
//   tpad.finger(40, 30);            // x_mm, y_mm (optional force_n, t: your clock in seconds)
//   tpad.lift();
//   tpad.on("telemetry", (m) => console.log(m.x_mm, m.target_mu));
//   await tpad.subscribe(20);
//   tpad.close();
//
// The message names are the protocol's, the same in the Python and C# clients beside this file.

export const PROTOCOL_VERSION = 1;

export class TpadError extends Error {
  constructor(reply) {
    super(`${reply.code}: ${reply.message}`);
    this.code = reply.code;
    this.reply = reply;
  }
}

export class TpadClient {
  // Connect and read the server's hello; rejects if it speaks another protocol version.
  static connect(url) {
    return new Promise((resolve, reject) => {
      const socket = new WebSocket(url);
      const client = new TpadClient(socket);
      socket.addEventListener("error", () => reject(new Error(`cannot connect to ${url}`)), { once: true });
      client.once("hello", (hello) => {
        if (hello.protocol !== PROTOCOL_VERSION) {
          socket.close();
          reject(new Error(`this client speaks protocol ${PROTOCOL_VERSION}, the server ${hello.protocol}`));
          return;
        }
        client.hello = hello;
        resolve(client);
      });
    });
  }

  constructor(socket) {
    this.socket = socket;
    this.handlers = new Map();
    this.pending = new Map();
    this.nextId = 1;
    this.hello = null;
    socket.addEventListener("message", (event) => this.#receive(JSON.parse(event.data)));
    socket.addEventListener("close", () => {
      for (const { reject } of this.pending.values()) reject(new Error("the connection closed"));
      this.pending.clear();
      this.#emit("close", {});
    });
  }

  // Handlers by message type ("telemetry", "texture", "finger", "error", ...; "close" when it closes).
  on(type, handler) {
    if (!this.handlers.has(type)) this.handlers.set(type, []);
    this.handlers.get(type).push(handler);
  }

  once(type, handler) {
    const wrapper = (message) => {
      this.handlers.set(type, this.handlers.get(type).filter((h) => h !== wrapper));
      handler(message);
    };
    this.on(type, wrapper);
  }

  send(message) {
    this.socket.send(JSON.stringify(message));
  }

  // Send a message with a fresh id; resolves with the reply that carries it, rejects with its error.
  request(message) {
    const id = this.nextId++;
    return new Promise((resolve, reject) => {
      this.pending.set(id, { resolve, reject });
      this.send({ ...message, id });
    });
  }

  // The finger at (x_mm, y_mm) on the plate; force_n (N) and t (your clock, s) are optional.
  finger(x_mm, y_mm, { force_n, t } = {}) {
    this.send({ type: "finger", x_mm, y_mm, ...(force_n !== undefined && { force_n }), ...(t !== undefined && { t }) });
  }

  // Several samples at once: [{x_mm, y_mm, force_n?, t?}, ...], oldest first.
  fingers(samples) {
    this.send({ type: "fingers", samples });
  }

  lift(t) {
    this.send({ type: "lift", ...(t !== undefined && { t }) });
  }

  // {name} (a shipped texture), {path} (a file the server may read) or {yaml} (a texture file's text).
  texture(ref) {
    return this.request({ type: "texture", ...ref });
  }

  device() {
    return this.request({ type: "device" });
  }

  subscribe(rate_hz) {
    return this.request({ type: "subscribe", rate_hz });
  }

  stats() {
    return this.request({ type: "stats" });
  }

  ping(t) {
    return this.request({ type: "ping", ...(t !== undefined && { t }) });
  }

  close() {
    this.socket.close();
  }

  #receive(message) {
    if (message.id !== undefined && this.pending.has(message.id)) {
      const { resolve, reject } = this.pending.get(message.id);
      this.pending.delete(message.id);
      if (message.type === "error") reject(new TpadError(message));
      else resolve(message);
    }
    this.#emit(message.type, message);
  }

  #emit(type, message) {
    for (const handler of this.handlers.get(type) || []) handler(message);
  }
}
