// Serializes ROS 2 messages with @foxglove/rosmsg2-serialization over the message definitions of
// @foxglove/rosmsg-msgs-common (an independent implementation of ROS 2's CDR, to compare the
// bridge's bytes with). Reads JSON from stdin: {"distro": "ros2jazzy", "messages": [{"type":
// "sensor_msgs/PointCloud2", "message": {...}}, ...]}; a field "data" given as {"hex": "..."} is a
// uint8[]. Writes JSON: [{"type": ..., "hex": "<the CDR bytes, encapsulation header first>"}].
// Types that rosmsg-msgs-common lacks (rmw_dds_common's) come with the request as .msg text:
// "definitions": {"rmw_dds_common/Gid": "char[16] data", ...}, parsed by @foxglove/rosmsg.
"use strict";
const { MessageWriter } = require("@foxglove/rosmsg2-serialization");
const common = require("@foxglove/rosmsg-msgs-common");
const { parse } = require("@foxglove/rosmsg");

// The request's .msg texts, root first, in the layout of a concatenated message definition.
function definitionsFromText(texts, root) {
  let full = texts[root];
  for (const [name, text] of Object.entries(texts)) {
    if (name !== root) full += `\n${"=".repeat(80)}\nMSG: ${name}\n${text}`;
  }
  return parse(full, { ros2: true });
}

// The root definition first, then every type it uses (MessageWriter's input).
function definitionsOf(defs, root) {
  const out = [];
  const seen = new Set();
  const visit = (name) => {
    if (seen.has(name)) return;
    seen.add(name);
    const def = defs[name];
    if (def === undefined) throw new Error(`no definition of ${name}`);
    out.push(def);
    for (const f of def.definitions) {
      if (f.isComplex && !f.isConstant) visit(f.type);
    }
  };
  visit(root);
  return out;
}

// {"hex": "..."} -> Uint8Array, recursively.
function revive(value) {
  if (Array.isArray(value)) return value.map(revive);
  if (value !== null && typeof value === "object") {
    if (typeof value.hex === "string" && Object.keys(value).length === 1) {
      return Uint8Array.from(Buffer.from(value.hex, "hex"));
    }
    const out = {};
    for (const [k, v] of Object.entries(value)) out[k] = revive(v);
    return out;
  }
  return value;
}

let input = "";
process.stdin.on("data", (chunk) => (input += chunk));
process.stdin.on("end", () => {
  const request = JSON.parse(input);
  const defs = common[request.distro];
  if (defs === undefined) throw new Error(`@foxglove/rosmsg-msgs-common has no ${request.distro}`);
  const texts = request.definitions || {};
  const out = request.messages.map(({ type, message }) => {
    const definitions =
      texts[type] !== undefined ? definitionsFromText(texts, type) : definitionsOf(defs, type);
    const writer = new MessageWriter(definitions);
    return { type, hex: Buffer.from(writer.writeMessage(revive(message))).toString("hex") };
  });
  process.stdout.write(JSON.stringify(out));
});
