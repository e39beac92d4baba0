// Validates a glTF 2.0 file (.glb or .gltf) with the Khronos glTF-Validator (npm
// `gltf-validator`) and prints its report as JSON on stdout:
//   node tests/node/validate_gltf.mjs <file>
// Node finds `gltf-validator` in tests/node_modules (or NODE_PATH); `cargo xtask setup`
// installs it. Exit code 0 when the report could be produced, whatever it says; the Rust
// test decides what is acceptable.
import { readFile } from "node:fs/promises";
import { createRequire } from "node:module";
import path from "node:path";

const file = process.argv[2];
if (!file) {
  console.error("usage: node validate_gltf.mjs <file.glb>");
  process.exit(2);
}
const modules = process.env.EGOEXO_NODE_MODULES;
const require = createRequire(modules ? path.join(modules, "noop.js") : import.meta.url);
const validator = require("gltf-validator");

const bytes = new Uint8Array(await readFile(file));
const report = await validator.validateBytes(bytes, {
  uri: path.basename(file),
  maxIssues: 0,
  // A .glb is self-contained; an external resource would be a failure of the exporter.
  externalResourceFunction: (uri) => Promise.reject(new Error(`external resource ${uri} requested`)),
});
console.log(JSON.stringify({ validatorVersion: report.validatorVersion, issues: report.issues, info: report.info }));
