#!/usr/bin/env node
// Validates glTF files with the Khronos glTF Validator (npm `gltf-validator`, installed into
// .ci/node_modules by scripts/setup-debian.sh). Usage: node scripts/validate-gltf.js FILE...
// Prints one line per file (errors, warnings, infos, hints) and every error and warning; exits 1
// when a file has an error, 2 when the validator is not installed.
'use strict';
const fs = require('fs');
const path = require('path');

const where = path.join(__dirname, '..', '.ci', 'node_modules', 'gltf-validator');
let validator;
try {
  validator = require(where);
} catch (e) {
  console.error(`error: ${where}: the glTF validator is not installed (run scripts/setup-debian.sh)`);
  process.exit(2);
}

async function main(files) {
  let failed = false;
  for (const f of files) {
    const bytes = new Uint8Array(fs.readFileSync(f));
    const report = await validator.validateBytes(bytes, { uri: path.basename(f), maxIssues: 1000 });
    const n = report.issues;
    console.log(`${f}: ${n.numErrors} errors, ${n.numWarnings} warnings, ${n.numInfos} infos, ${n.numHints} hints (validator ${report.validatorVersion})`);
    for (const m of n.messages) {
      if (m.severity <= 1) {
        console.log(`  ${m.severity === 0 ? 'ERROR' : 'WARNING'} ${m.code} ${m.pointer || ''}: ${m.message}`);
      }
    }
    if (n.numErrors > 0) failed = true;
  }
  process.exit(failed ? 1 : 0);
}

main(process.argv.slice(2)).catch((e) => {
  console.error(`error: ${e}`);
  process.exit(1);
});
