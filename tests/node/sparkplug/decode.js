// Decode Sparkplug B payloads with Eclipse Tahu's JavaScript codec (npm sparkplug-payload), as a Node.js host does.
// stdin: JSON [{"topic": ..., "payload": base64}, ...]; stdout: JSON [{"topic", "timestamp", "seq", "metrics"}, ...]
// with 64-bit integers (Long) as decimal strings, so that no digit is lost in JSON.
"use strict";
const Long = require("long");
const sparkplug = require("sparkplug-payload").get("spBv1.0");

function plain(key, value) {
  if (Long.isLong(value)) return value.toString();
  if (value instanceof Uint8Array) return Buffer.from(value).toString("base64");
  return value;
}

let input = "";
process.stdin.setEncoding("utf8");
process.stdin.on("data", (chunk) => { input += chunk; });
process.stdin.on("end", () => {
  const out = JSON.parse(input).map(({ topic, payload }) => {
    try {
      return { topic, ...sparkplug.decodePayload(Buffer.from(payload, "base64")) };
    } catch (err) {
      return { topic, error: String(err) };
    }
  });
  process.stdout.write(JSON.stringify(out, plain));
});
