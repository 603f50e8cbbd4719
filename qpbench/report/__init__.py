"""Reports of benchmark and closed-loop results: ``report.md`` and PNG figures, every number
recomputed from the result CSVs (:func:`.write.write_report`). :mod:`.markdown_table` and
:func:`.write.publish` are the one renderer of every report (this one, the sweep's and the
scaling study's); importing the package loads none of them."""
