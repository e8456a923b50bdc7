# Reference values for tests/analysis/test_sample_size.py, written to power_reference.csv beside this script
# (columns quantity, a, b, c, value; 15 significant digits, as write.csv writes them).
#
#   Rscript tests/data/r_reference_power/power_reference.R      (from the repository root; needs pwr)
#
# * f2: pwr::pwr.f2.test(u, v, f2, sig.level = .05)$power for one coefficient (u = 1) in a regression with k
#   predictors and N participants (v = N - k - 1); a = f2, b = N, c = k.
# * rmsea: power of the RMSEA tests of MacCallum, Browne & Sugawara (1996) with base R's noncentral chi-square;
#   a = N, b = df, c = eps_a (eps0 = .05, alpha = .05); close fit when eps_a > .05, not-close fit when eps_a < .05.
# * rmsea_n: the smallest N with that power >= .80 (a linear search); a = df, c = eps_a.
suppressPackageStartupMessages(library(pwr))
here <- dirname(sub("--file=", "", grep("--file=", commandArgs(FALSE), value = TRUE)))
rows <- list()
add <- function(q, a, b, c, v) rows[[length(rows) + 1]] <<- data.frame(quantity = q, a = a, b = b, c = c, value = v)
for (f2 in c(0.02, 0.09 / 0.91, 0.15, 0.35)) for (n in c(20, 50, 120)) for (k in c(1, 3)) {
  add("f2", f2, n, k, pwr.f2.test(u = 1, v = n - k - 1, f2 = f2, sig.level = 0.05)$power)
}
rmsea_power <- function(n, df, ea, e0 = 0.05, alpha = 0.05) {
  nc0 <- (n - 1) * df * e0^2; nca <- (n - 1) * df * ea^2
  if (ea > e0) 1 - pchisq(qchisq(1 - alpha, df, ncp = nc0), df, ncp = nca)
  else pchisq(qchisq(alpha, df, ncp = nc0), df, ncp = nca)
}
for (n in c(50, 200, 500)) for (df in c(10, 50, 137)) for (ea in c(0.01, 0.08)) add("rmsea", n, df, ea, rmsea_power(n, df, ea))
for (df in c(10, 50, 137)) for (ea in c(0.01, 0.08)) {
  n <- 2; while (rmsea_power(n, df, ea) < 0.8) n <- n + 1
  add("rmsea_n", df, NA, ea, n)
}
out <- do.call(rbind, rows)
write.csv(out, file.path(here, "power_reference.csv"), row.names = FALSE, na = "")
