"""Research beside the product: the studies' scripts and the tests of the numbers the research notes quote."""
