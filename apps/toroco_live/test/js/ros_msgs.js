// Checks ROS 2 message definitions and CDR bytes made in Erlang with the
// reference ROS 2 libraries: each case of the JSON file named on the
// command line ({"type", "definition", "cdr" (base64), "msg"}) has its
// definition parsed with @foxglove/rosmsg (ros2), its bytes decoded with
// @foxglove/rosmsg2-serialization's MessageReader, and "msg" written with
// its MessageWriter to compare the bytes (unless "writer" is false). One JSON line out:
// {"ok":true,"cases":[{"type","parsed":[type names],"decoded":{...},"same_bytes":bool}]}
"use strict";
const fs = require("fs");
const { parse } = require("@foxglove/rosmsg");
const { MessageReader, MessageWriter } = require("@foxglove/rosmsg2-serialization");

function main(path) {
  const cases = JSON.parse(fs.readFileSync(path, "utf8"));
  const out = [];
  for (const c of cases) {
    try {
      const defs = parse(c.definition, { ros2: true });
      const bytes = Buffer.from(c.cdr, "base64");
      const decoded = new MessageReader(defs).readMessage(bytes);
      let same = null;
      if (c.msg && c.writer !== false) {
        const written = Buffer.from(new MessageWriter(defs).writeMessage(c.msg));
        same = written.equals(bytes);
      }
      out.push({ type: c.type, parsed: defs.map((d) => d.name ?? ""), decoded,
                 same_bytes: same, length: bytes.length });
    } catch (e) {
      out.push({ type: c.type, error: String((e && e.message) || e) });
    }
  }
  console.log(JSON.stringify({ ok: true, cases: out }, (k, v) => typeof v === "bigint" ? Number(v) : ArrayBuffer.isView(v) ? Array.from(v) : v));
}
main(process.argv[2]);
