"""Object search with learned context (paper, section 3), as a package of roles:

- ``episode``: what a search is (``Episode``: a world, a start, a target, a budget) and how it
  went (``SearchResult``); ``measures``: success, time to find, spl, paired ratios, the oracle's
  violations, each defined once;
- ``maps``: what the robot is given before it searches (the ``built`` and ``given`` scenarios);
- ``context``: one policy's run of one episode: the clock, the budget, the robot's actions; it
  senses through a ``Perception`` and never reads the true layout;
- the behaviours, each acting on a context: ``coverage``, ``regions`` (the location
  constraint), ``frontier`` (exploration of the built map), ``online`` (the online decision in
  one currency); with the models they use: ``space`` (seen map, candidate regions, costs) and
  ``viewpoints`` (viewpoint gain, Wixson & Ballard's efficiency model);
- ``registry`` (the policies' facts, light enough for the CLI's parser) and ``policies`` (the
  behaviours put together); ``oracle`` (the lower bound);
- ``priors`` (learned knowledge or the truth), ``draw`` and ``draw_store`` (paired episodes in
  held-out worlds, kept on disk), ``runner`` (one policy on one episode, judged).

Only ``oracle``, ``draw``, ``runner``, ``maps`` (the given map's furniture poses) and ``priors``
(the ground truth's table) read the true layout or the style. Nothing is imported here: import
the module you need (``from ctxsearch.agent.search.runner import search_once``).
"""
