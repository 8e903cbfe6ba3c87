// What the suites' Node drivers share: one JSON event per stdout line,
// one JSON command per stdin line, and a raw WebSocket for what a
// misbehaving client does (events raw_open, raw_close {code}, raw_error;
// its messages go to the driver's own handler).
"use strict";
const readline = require("readline");

// Typed arrays (a CDR reader's float64[36]) as plain arrays.
const out = (ev) => process.stdout.write(
  JSON.stringify(ev, (k, v) => (ArrayBuffer.isView(v) ? Array.from(v) : v)) + "\n");
// The suite closes the port when a case ends: stdout goes, so does the driver.
process.stdout.on("error", () => process.exit(0));

// run(command) for each line; a line that is not JSON is bad_command, a
// command that throws is command_failed; stdin closed ends the driver.
function commands(run) {
  const rl = readline.createInterface({ input: process.stdin });
  rl.on("line", (line) => {
    let c;
    try { c = JSON.parse(line); } catch { out({ ev: "bad_command", line }); return; }
    try {
      if (run(c) === false) out({ ev: "bad_command", line });
    } catch (e) {
      out({ ev: "command_failed", cmd: c.cmd, error: String((e && e.message) || e) });
    }
  });
  rl.on("close", () => process.exit(0));
}

// read: false stops reading once open (a client that never drains).
function rawSocket(WebSocket, url, protocols, read, onMessage) {
  const raw = new WebSocket(url, protocols);
  raw.on("open", () => { out({ ev: "raw_open" }); if (!read) raw._socket.pause(); });
  raw.on("message", onMessage);
  raw.on("close", (code) => out({ ev: "raw_close", code }));
  raw.on("error", (e) => out({ ev: "raw_error", error: String((e && e.message) || e) }));
  return raw;
}

module.exports = { out, commands, rawSocket };
