"""Where modellers write: bgc fmt, the canonical layout of a model's text (bgc.editor.fmt),
and bgc lsp, a Language Server Protocol server (bgc.editor.lsp, on pygls: the `lsp` extra).
Entry: fmt.format_text (`bgc fmt`) and lsp.main (`bgc lsp`)."""
