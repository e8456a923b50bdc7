-- Orders as they happened (docs/protocols.md "Orders"): an order is drawn by the balanced assignment or given by the
-- lab (`session assign ID --order NAME`, a roster's `order` column), when orders were fixed beforehand or the lab had
-- to deviate. `given` tells which; `drawn` is the order the balanced assignment would have drawn at that moment
-- (equal to order_name for a drawn order), so the balance report names each deviation from the design; `reason` is
-- the lab's note for a given order. Rows stored before this migration were drawn.
ALTER TABLE order_assignments ADD COLUMN given BOOLEAN NOT NULL DEFAULT false;
ALTER TABLE order_assignments ADD COLUMN drawn VARCHAR;
ALTER TABLE order_assignments ADD COLUMN reason VARCHAR;
UPDATE order_assignments SET drawn = order_name;
