// Validates a .glb with the Khronos glTF Validator (npm gltf-validator) and prints its issues, one
// per line ("SEVERITY CODE pointer: message"), then a summary line. Exit code: 0 when the file has
// no errors and no warnings, 1 otherwise, 2 when it could not be run.
// Usage: node validate_gltf.js NODE_MODULES_DIR FILE.glb
const path = require('path');
const fs = require('fs');

const [modules, file] = process.argv.slice(2);
if (!modules || !file) {
  console.error('usage: node validate_gltf.js NODE_MODULES_DIR FILE.glb');
  process.exit(2);
}
const validator = require(path.join(modules, 'gltf-validator'));
const severities = ['ERROR', 'WARNING', 'INFO', 'HINT'];
validator
  .validateBytes(new Uint8Array(fs.readFileSync(file)), { maxIssues: 100 })
  .then((report) => {
    for (const m of report.issues.messages)
      console.log(`${severities[m.severity] || m.severity} ${m.code} ${m.pointer || ''}: ${m.message}`);
    const i = report.issues;
    console.log(`validator ${report.validatorVersion}: ${i.numErrors} errors, ${i.numWarnings} ` +
                `warnings, ${i.numInfos} infos, ${i.numHints} hints`);
    process.exit(i.numErrors === 0 && i.numWarnings === 0 ? 0 : 1);
  })
  .catch((error) => {
    console.error(`validation failed to run: ${error}`);
    process.exit(2);
  });
