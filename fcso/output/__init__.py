"""Writing a design's output folder: the files, the HTML pages and their pictures.

The method (the rest of :mod:`fcso`) knows nothing of folders or pages; this
package turns its results into files. Submodules:

- :mod:`~fcso.output.files`: a design's or a job's files, written and rebuilt
- :mod:`~fcso.output.html`: building blocks of the report pages
- :mod:`~fcso.output.grasp_scenes`: the chosen candidate's grasps as the page shows them
- :mod:`~fcso.output.design_page`: ``report.html`` of one design, with the data its pictures are drawn from
- :mod:`~fcso.output.sets_page`: the finger-sets sections, the job page and the terminal's pick plan
- :mod:`~fcso.output.render`: drawing meshes off screen (matplotlib's Agg canvas): views, layers, panels, PNG
- :mod:`~fcso.output.decimate`: fewer triangles for the pictures and the 3D view (no matplotlib)
- :mod:`~fcso.output.pictures`: the pictures of the design pages
- :mod:`~fcso.output.viewer`: the pages' interactive 3D view (three.js and GLB meshes, inlined)
- :mod:`~fcso.output.verification_page`: the verification section (fcso.sim) and its files
- :mod:`~fcso.output.read`: reading an output folder back
- :mod:`~fcso.output.picture_process`: a process that draws the pictures beside the design
- :mod:`~fcso.output.table`: the quality table (the paper's Table I layout)

The folder layout is :mod:`fcso.layout`, below the method, which records its names.
"""
