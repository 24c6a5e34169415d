"""report stage: what a run says about itself. ``report.json`` (:mod:`.build`: the one builder, its schema
``schema.json``, the verdict), ``summary.txt`` and ``report.html`` (:mod:`.text`, :mod:`.html`), the plots
(:mod:`.plots`), the detection overlays of report.html (:mod:`.overlay`) and the hand-eye block (:mod:`.handeye`).
Above the stages it reports on (measure, identify, io); the pipelines (``experiment``) call it."""
