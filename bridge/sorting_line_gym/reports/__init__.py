"""Results people read: `sorting-line-eval` (``evaluate``, the paper's protocol), the Table 1
benchmark (``benchmark``), its figures (``plots``), the published figures it compares with
(``paper``), and `sorting-line-bridge` (``bridge_node``: episodes through the bridge, their KPIs
and dashboard)."""
