# R's rank tests on the numerators k of values k/6 (tests/data/ranks/values.csv): what the tool must give on the
# values k/6 as floating point computes them, ties included (analysis/ranks.py; tests/analysis/test_ranks.py).
# The tests are invariant to the scale, so R on the whole numerators is R on the data at their resolution.
#   Rscript tests/data/ranks/rank_reference.R   (writes tests/data/ranks/rank_reference.json)
here <- dirname(sub("^--file=", "", grep("^--file=", commandArgs(FALSE), value = TRUE)))
v <- read.csv(file.path(here, "values.csv"), stringsAsFactors = FALSE)
res <- list()
add <- function(name, test, estimate = NA) {
  res[[name]] <<- list(statistic = unname(test$statistic), p = test$p.value, method = test$method,
                       estimate = if (is.na(estimate)) NULL else unname(estimate))
}
for (case in unique(v$case)) {
  d <- v[v$case == case, ]
  for (pair in list(c("a", "b"), c("a", "c"), c("b", "c"))) {
    add(paste(case, "wilcoxon", pair[1], pair[2], sep = "_"),
        suppressWarnings(wilcox.test(d[[pair[1]]], d[[pair[2]]], paired = TRUE)))
  }
  fr <- friedman.test(as.matrix(d[, c("a", "b", "c")]))
  add(paste(case, "friedman", sep = "_"), fr)
  sp <- suppressWarnings(cor.test(d$a, d$b, method = "spearman"))
  add(paste(case, "spearman_a_b", sep = "_"), sp, sp$estimate)
  sp8 <- suppressWarnings(cor.test(d$a[1:8], d$c[1:8], method = "spearman"))
  add(paste(case, "spearman8_a_c", sep = "_"), sp8, sp8$estimate)
  add(paste(case, "mannwhitney_a_c", sep = "_"), suppressWarnings(wilcox.test(d$a, d$c)))
  add(paste(case, "mannwhitney7_a_b", sep = "_"), suppressWarnings(wilcox.test(d$a[1:7], d$b[1:6])))
}
res[["R"]] <- R.version.string
writeLines(jsonlite::toJSON(res, auto_unbox = TRUE, digits = NA, pretty = TRUE), file.path(here, "rank_reference.json"))
