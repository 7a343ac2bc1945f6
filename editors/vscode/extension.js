// The VS Code client of bgc lsp (docs/editors.md): starts `bgc lsp` (the settings bgc.command
// and bgc.args) on stdin and stdout for .bg files, and stops it with the editor.
"use strict";

const vscode = require("vscode");
const { LanguageClient } = require("vscode-languageclient/node");

let client;

function activate(context) {
  const config = vscode.workspace.getConfiguration("bgc");
  const server = { command: config.get("command", "bgc"), args: config.get("args", ["lsp"]) };
  client = new LanguageClient(
    "bgc",
    "bgc lsp",
    { run: server, debug: server },
    { documentSelector: [{ scheme: "file", language: "bg" }, { scheme: "untitled", language: "bg" }] }
  );
  context.subscriptions.push({ dispose: () => client && client.stop() });
  return client.start();
}

function deactivate() {
  return client ? client.stop() : undefined;
}

module.exports = { activate, deactivate };
