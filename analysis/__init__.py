"""Analysis of pEDAS studies: objective KPIs, acceptance statistics (CFA, reliability, validity, hierarchical
regressions, H1-H7), the paper's published values with their audit and reconstruction, tables, figures, report."""
