# The rank tests of the takeover study's scores at the resolution the scores carry (tests/analysis/test_within.py,
# analysis/ranks.py), written to rank_reference.json beside this script:
#
#   Rscript tests/data/takeover/rank_reference.R
#
# Each score is a whole number of its steps: SUS / 2.5 = the sum of the ten contributions, raw TLX x 6 / 5 = the sum
# of the six subscales over their step of 5, trust x 6 = the sum of the six items (trust2, trust5 as 8 - x). The
# tests are invariant to the scale, so friedman.test and wilcox.test(paired = TRUE) on those whole numbers are R's
# tests on the scores with every tie the data have (within_reference.json ran them on the floating-point means, whose
# rounding splits some ties). Complete cases (TOR-A19 left out), pairs none-visual, none-audiovisual,
# visual-audiovisual, differences a - b, Holm over the three pairs.
args <- commandArgs(trailingOnly = FALSE)
script <- sub("^--file=", "", args[grep("^--file=", args)])
here <- if (length(script)) dirname(normalizePath(script)) else "tests/data/takeover"
items <- read.csv(file.path(here, "items.csv"), stringsAsFactors = FALSE)
odd <- paste0("sus", c(1, 3, 5, 7, 9))
even <- paste0("sus", c(2, 4, 6, 8, 10))
tlx_items <- paste0("tlx_", c("mental", "physical", "temporal", "performance", "effort", "frustration"))
trust <- items[, paste0("trust", 1:6)]
trust$trust2 <- 8 - trust$trust2
trust$trust5 <- 8 - trust$trust5
steps <- data.frame(participant = items$participant, condition = items$condition,
                    sus = rowSums(items[, odd] - 1) + rowSums(5 - items[, even]),
                    tlx = rowSums(items[, tlx_items]) / 5,
                    trust = rowSums(trust))
levels <- c("none", "visual", "audiovisual")
counts <- table(steps$participant)
complete <- steps[steps$participant %in% names(counts)[counts == length(levels)], ]
complete <- complete[order(complete$participant, match(complete$condition, levels)), ]
out <- list()
for (v in c("sus", "tlx", "trust")) {
  m <- matrix(complete[[v]], ncol = length(levels), byrow = TRUE)
  fr <- friedman.test(m)
  pairs <- list()
  for (ab in list(c(1, 2), c(1, 3), c(2, 3))) {
    w <- suppressWarnings(wilcox.test(m[, ab[1]], m[, ab[2]], paired = TRUE))
    pairs[[length(pairs) + 1]] <- list(a = levels[ab[1]], b = levels[ab[2]], v = unname(w$statistic), p = w$p.value,
                                       method = w$method)
  }
  holm <- p.adjust(vapply(pairs, function(p) p$p, 0), method = "holm")
  for (j in seq_along(pairs)) pairs[[j]]$p_holm <- holm[j]
  out[[v]] <- list(friedman = list(chi2 = unname(fr$statistic), p = fr$p.value,
                                   kendall_w = unname(fr$statistic) / (nrow(m) * (length(levels) - 1))),
                   pairs = pairs)
}
out[["R"]] <- R.version.string
writeLines(jsonlite::toJSON(out, auto_unbox = TRUE, digits = NA, pretty = TRUE), file.path(here, "rank_reference.json"))
