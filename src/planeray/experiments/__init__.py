"""End-to-end experiments: each one simulates (or reads) captures, analyses them and writes its numbers
(JSON/CSV) and figures (PNG) into a folder.

* :mod:`planeray.experiments.paper`: the paper's figures reproduced on the simulated device
  (``planeray figure ...``);
* :mod:`planeray.experiments.study`: the Sec. 5.2 demultiplexing study (``planeray study demux``);
* :mod:`planeray.experiments.reproduce`: every figure at once, resumable (``planeray paper``), and
  :mod:`planeray.experiments.paper_report`, its report beside the paper's quoted numbers.

Experiments sit above analysis and figures: they compose them, nothing below imports them.
"""
