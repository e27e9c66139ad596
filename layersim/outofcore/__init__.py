"""Out-of-core machinery: blocks held in memory or in spool files between their uses.

One concept per module:

* :mod:`.workspace` -- :class:`~.workspace.Workspace`, where a solve keeps its idle blocks and
  the pieces of its intermediate results (decided once per solve), and
  :class:`~.workspace.Blocks`, the named blocks of one computation handed over at their last
  use;
* :mod:`.spool` -- tuples of arrays in an unnamed temporary file, read back in order;
* :mod:`.parking` -- a block parked in a file while idle, and where parking is possible;
* :mod:`.rowpieces` -- a sparse matrix as consecutive pieces of rows, in memory or in a file;
* :mod:`.rows` -- spans and chunks of rows of a bounded number of entries;
* :mod:`.assemble` -- CSR matrices assembled from parts and pieces, each released as placed;
* :mod:`.products` -- sparse products in chunks of rows, filtered as they come;
* :mod:`.sums` -- sums in pieces of rows, pruning of small entries;
* :mod:`.transpose` -- transposes of matrices held in files;
* :mod:`.memory` -- returning freed heap pages to the system, the bytes of sparse blocks.

The pieces are generic sparse tools; what is physics of the coupled representation (slot
pairs, pruning per ordinate pair, reciprocal images) is in :mod:`layersim.aniso`.
"""
