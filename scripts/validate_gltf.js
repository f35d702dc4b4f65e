#!/usr/bin/env node
// Validates glTF / GLB files with the Khronos glTF validator (npm package gltf-validator,
// installed into .tools/npm by scripts/setup.sh). Prints one summary line per file (errors,
// warnings, infos, and the error messages) and exits 1 when any file has errors.
// Usage: node scripts/validate_gltf.js FILE... [--json REPORT_DIR]
"use strict";
const fs = require("fs");
const path = require("path");

const modulePath = path.join(__dirname, "..", ".tools", "npm", "node_modules", "gltf-validator");
let validator;
try {
  validator = require(modulePath);
} catch (e) {
  console.error(`validate_gltf: gltf-validator not found in ${modulePath}; run scripts/setup.sh`);
  process.exit(2);
}

async function validate(file) {
  const bytes = new Uint8Array(fs.readFileSync(file));
  return validator.validateBytes(bytes, {
    uri: path.basename(file),
    maxIssues: 0,
    writeTimestamp: false,
    externalResourceFunction: (uri) =>
      new Promise((resolve, reject) => {
        const resolved = path.resolve(path.dirname(file), decodeURIComponent(uri));
        fs.readFile(resolved, (err, data) => (err ? reject(err.toString()) : resolve(new Uint8Array(data))));
      }),
  });
}

(async () => {
  const args = process.argv.slice(2);
  const files = args.filter((a) => !a.startsWith("--"));
  if (files.length === 0) {
    console.error("usage: node scripts/validate_gltf.js FILE...");
    process.exit(2);
  }
  let failed = false;
  for (const file of files) {
    let report;
    try {
      report = await validate(file);
    } catch (e) {
      console.log(`${file}: could not validate: ${e}`);
      failed = true;
      continue;
    }
    const issues = report.issues;
    const errors = report.issues.messages.filter((m) => m.severity === 0);
    console.log(
      `${file}: ${issues.numErrors} errors, ${issues.numWarnings} warnings, ${issues.numInfos} infos` +
        ` (validator ${report.validatorVersion})`
    );
    for (const m of errors) {
      console.log(`  error ${m.code} at ${m.pointer || m.offset}: ${m.message}`);
    }
    for (const m of report.issues.messages.filter((m) => m.severity === 1)) {
      console.log(`  warning ${m.code} at ${m.pointer || m.offset}: ${m.message}`);
    }
    if (issues.numErrors > 0) failed = true;
  }
  process.exit(failed ? 1 : 0);
})();
